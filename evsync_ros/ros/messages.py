"""The generated message classes the node and the player publish with, found by type name."""

from __future__ import annotations

from typing import Any

from evsync_ros.errors import ParameterError


def message_class(msgtype: str) -> Any:
    """The generated Python class of 'pkg/msg/Name' (or 'pkg/Name')."""
    parts = msgtype.split('/')
    pkg, name = parts[0], parts[-1]
    try:
        module = __import__(f'{pkg}.msg', fromlist=[name])
        return getattr(module, name)
    except (ImportError, AttributeError) as exc:
        raise ParameterError(f'message type {msgtype}: no Python interface package installed ({exc})') from exc
