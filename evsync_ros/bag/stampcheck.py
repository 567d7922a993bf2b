"""Companion stamps against their camera's event times: the check that finds a companion stamped on
another timeline than its camera's events (libcaer_driver before 1.5.4 stamped IMU and frames with
the host time plus the sensor's elapsed time: libcaer_driver#12, fixed by its PR #13). Used by
``evsync restamp`` and the live node alike; what it measures: docs/bags.md, "Companions"."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

__all__ = ['CameraTimes', 'StampCheck']

PERIOD_MESSAGES = 65
"""A camera's packet period is the median spacing of its last this many messages' first events."""


class CameraTimes:
    """A camera's clock against arrival times, and its packet period, from its messages as they come.

    Each message gives (its newest event time - its arrival time); the largest of the recent ones is
    the camera's clock at an arrival, less the least latency (an event message's newest event is
    older than its arrival by that latency, and by more in a quiet scene, where packets wait for
    events: hence the largest)."""

    def __init__(self) -> None:
        self._firsts: deque[int] = deque(maxlen=PERIOD_MESSAGES)
        self._ahead: deque[int] = deque(maxlen=PERIOD_MESSAGES)

    def add(self, times: np.ndarray, arrival_ns: int) -> None:
        """One message's event times (int64 ns, the camera's own timeline) and when it arrived (the
        record time in a bag, the node's clock live)."""
        if times.size:
            self._firsts.append(int(times[0]))
            self._ahead.append(int(times[-1]) - arrival_ns)

    def at(self, arrival_ns: int) -> int | None:
        """The camera's time when something arrived at ``arrival_ns``, less the least latency (None
        before its first message with events)."""
        return arrival_ns + max(self._ahead) if self._ahead else None

    @property
    def period_ns(self) -> int | None:
        """The median spacing of the recent messages' first events (None before two messages)."""
        if len(self._firsts) < 2:
            return None
        spacing = np.diff(np.fromiter(self._firsts, np.int64))
        spacing = spacing[spacing > 0]
        return int(np.median(spacing)) if spacing.size else None


@dataclass
class StampCheck:
    """One companion's stamps checked against its camera's clock when each arrives (``CameraTimes.at``).
    A sample rides a packet with the camera's events, so it may be up to a packet period older than
    the newest event that arrives with it: a stamp more than a packet period outside that period
    disagrees."""

    topic: str
    camera: str
    checked: int = 0
    disagreeing: int = 0
    worst_ns: int = 0
    """The disagreeing stamp farthest from its camera's events (signed: the stamp minus the event time)."""
    period_ns: int = 0
    """The camera's packet period when the worst was seen."""

    def check(self, stamp_ns: int, arrival_ns: int, times: CameraTimes) -> int | None:
        """Check one companion stamp that arrived at ``arrival_ns``; returns how far it is from the
        camera's clock then when it disagrees (it is counted), else None (also before the camera's
        period is known)."""
        period, expected = times.period_ns, times.at(arrival_ns)
        if period is None or expected is None:
            return None
        self.checked += 1
        off = stamp_ns - expected
        if -2 * period <= off <= period:
            return None
        self.disagreeing += 1
        if abs(off) > abs(self.worst_ns):
            self.worst_ns, self.period_ns = off, period
        return off

    def says(self) -> str:
        """The warning, in a sentence ('' while every stamp agrees)."""
        if not self.disagreeing:
            return ''
        return (f'{self.topic}: {self.disagreeing} of {self.checked} stamps disagree with {self.camera}\'s event '
                f'times by more than its packet period ({self.period_ns / 1e6:.1f} ms), up to '
                f'{self.worst_ns / 1e9:+.3f} s (libcaer_driver before 1.5.4 stamped IMU and frames so: '
                'libcaer_driver#12; restamped with the camera, they stay that far off)')

    def as_json(self) -> dict[str, object]:
        return {'camera': self.camera, 'checked': self.checked, 'disagreeing': self.disagreeing,
                'worst_ns': self.worst_ns, 'period_ns': self.period_ns}
