"""The methods the engine runs, behind one protocol (``base.WindowMethod``), by table."""

from __future__ import annotations

from collections.abc import Callable

from evsync_ros.core.engine.methods.base import Decision, WindowMethod
from evsync_ros.core.engine.methods.paper import Paper
from evsync_ros.core.engine.methods.refined import Refined
from evsync_ros.core.results import Method

__all__ = ['METHODS', 'Decision', 'WindowMethod']

METHODS: dict[Method, Callable[[], WindowMethod]] = {Method.REFINED: Refined, Method.PAPER: Paper}
"""Each method's maker."""
