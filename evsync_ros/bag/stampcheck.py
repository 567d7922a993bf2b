"""Companion stamps against their camera's event times: the check that finds a companion stamped on
another timeline than its camera's events (libcaer_driver before 1.5.4 stamped IMU and frames with
the host time plus the sensor's elapsed time: libcaer_driver#12, fixed by its PR #13). Used by
``evsync restamp`` and the live node alike; what it measures: docs/bags.md, "Companions"."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

__all__ = ['CameraTimes', 'StampCheck']

PERIOD_MESSAGES = 65
"""A camera's packet period is the median spacing of its last this many messages' first events."""
FRESHEST_NS = 2_000_000_000
"""How far back the freshest (time - arrival) of a camera's or a companion's messages is taken: long
enough that a stall of the node's callbacks, after which messages arrive late and in bursts, passes."""


class _Freshest:
    """The largest value of those added within ``FRESHEST_NS`` of the newest arrival (a monotonic queue)."""

    def __init__(self) -> None:
        self._queue: deque[tuple[int, int]] = deque()

    def add(self, arrival_ns: int, value: int) -> None:
        while self._queue and self._queue[-1][1] <= value:
            self._queue.pop()
        self._queue.append((arrival_ns, value))
        while self._queue[0][0] < arrival_ns - FRESHEST_NS:
            self._queue.popleft()

    def value(self, now_ns: int) -> int | None:
        while self._queue and self._queue[0][0] < now_ns - FRESHEST_NS:
            self._queue.popleft()
        return self._queue[0][1] if self._queue else None


class CameraTimes:
    """A camera's clock against arrival times, and its packet period, from its messages as they come.

    Each message gives (its newest event time - its arrival time); the largest of the last
    ``FRESHEST_NS`` is the camera's clock less arrival time, less the least latency (an event
    message's newest event is older than its arrival by that latency, and by more in a quiet scene,
    where packets wait for events, or when the message is delivered late: hence the largest)."""

    def __init__(self) -> None:
        self._firsts: deque[int] = deque(maxlen=PERIOD_MESSAGES)
        self._ahead = _Freshest()

    def add(self, times: np.ndarray, arrival_ns: int) -> None:
        """One message's event times (int64 ns, the camera's own timeline) and when it arrived (the
        record time in a bag, the node's clock live)."""
        if times.size:
            self._firsts.append(int(times[0]))
            self._ahead.add(arrival_ns, int(times[-1]) - arrival_ns)

    def ahead_ns(self, now_ns: int) -> int | None:
        """The camera's clock less arrival time at ``now_ns``, less the least latency (None without a
        message with events in the last ``FRESHEST_NS``)."""
        return self._ahead.value(now_ns)

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
    """One companion's stamps checked against its camera's clock: its own freshest (stamp - arrival
    time) of the last ``FRESHEST_NS`` against the camera's (``CameraTimes.ahead_ns``), so that a
    message delivered late counts as little as an event message delivered late. A sample rides a packet
    with the camera's events, so it may be up to a packet period older than the newest event that
    arrives with it: a stamp more than a packet period outside that period disagrees."""

    topic: str
    camera: str
    checked: int = 0
    disagreeing: int = 0
    worst_ns: int = 0
    """The disagreement farthest from the camera's events (signed: the companion's clock minus the camera's)."""
    period_ns: int = 0
    """The camera's packet period when the worst was seen."""
    _ahead: _Freshest = field(default_factory=_Freshest, repr=False)

    def check(self, stamp_ns: int, arrival_ns: int, times: CameraTimes) -> int | None:
        """Check one companion stamp that arrived at ``arrival_ns``; returns how far the companion's
        clock is from the camera's when it disagrees (it is counted), else None (also before the
        camera's period is known)."""
        self._ahead.add(arrival_ns, stamp_ns - arrival_ns)
        period, camera, own = times.period_ns, times.ahead_ns(arrival_ns), self._ahead.value(arrival_ns)
        if period is None or camera is None or own is None:
            return None
        self.checked += 1
        off = own - camera
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
