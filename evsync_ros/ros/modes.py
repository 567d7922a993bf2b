"""The node's modes: each a parameter's choices, as members code dispatches on (by table where a
mode picks among several ways), never as text compared. ``str`` members, so a parameter's value
is its member's and a config prints as it was written."""

from __future__ import annotations

from enum import Enum

from evsync_ros.runtime.runner import Estimator

__all__ = ['BeforeLock', 'Estimator', 'Executor', 'Kind', 'Mode', 'Processes', 'Qos', 'Reliability', 'Republish']


class Mode(str, Enum):
    """A parameter's choices."""

    def __str__(self) -> str:
        return self.value

    @classmethod
    def choices(cls) -> tuple[str, ...]:
        """The values a parameter file may write, in their order."""
        return tuple(m.value for m in cls)


class Qos(Mode):
    """``qos``: the event inputs' (and outputs') QoS."""

    SENSOR_DATA = 'sensor_data'
    """Best effort, as camera drivers publish."""
    RELIABLE = 'reliable'


class Reliability(Mode):
    """``output_reliability``: the restamped event outputs'."""

    BEST_EFFORT = 'best_effort'
    RELIABLE = 'reliable'
    """Serves reliable and best-effort subscribers alike."""


class BeforeLock(Mode):
    """``before_lock``: what a camera's messages get before its lock."""

    FORWARD = 'forward'
    """Unshifted."""
    HOLD = 'hold'
    """Held until the lock, at most ``hold_limit_s``."""
    COARSE = 'coarse'
    """Shifted by the offset seen in arrival times."""


class Processes(Mode):
    """``processes``: where the message path runs."""

    ONE = 'one'
    PER_CAMERA = 'per_camera'
    """A camera process per topic (``ros.camera``), sending the node counts."""


class Republish(Mode):
    """``republish``: which streams go out again."""

    ALL = 'all'
    NONE = 'none'
    """Offsets and diagnostics only."""


class Executor(Mode):
    """``executor``: what spins the node (``ros.spin``)."""

    EVENTS = 'events'
    SINGLE_THREADED = 'single_threaded'


class Kind(Mode):
    """A node parameter's type."""

    STRING = 'string'
    STRING_ARRAY = 'string_array'
    DOUBLE = 'double'
    DOUBLE_ARRAY = 'double_array'
    INTEGER = 'integer'
