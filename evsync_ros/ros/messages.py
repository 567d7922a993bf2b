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


def companion_class(topic: str, msgtype: str) -> Any:
    """The class of a companion topic's type, which must begin with a std_msgs/Header (ParameterError
    naming the topic and the type otherwise)."""
    cls = message_class(msgtype)
    fields = list(cls.get_fields_and_field_types().items())
    if not fields or fields[0] != ('header', 'std_msgs/Header'):
        raise ParameterError(f'companion {topic}: type {msgtype} does not begin with a std_msgs/Header, so it has '
                             'no header.stamp to restamp')
    return cls
