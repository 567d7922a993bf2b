"""When messages arrive, and when the host had them: the node's ROS clock as its message path
reads it.

Without ``use_sim_time`` that is the system clock, read directly (what rclpy's ``Clock.now()``
returns, at well under a tenth of its cost per message: 23 us against 0.1 us on the loaded 2-core
host). On sim time rclpy's clock stands at the newest /clock until the next one: a player's 40 Hz
/clock would time every message of a tick at the tick's start, up to 25 ms early, and the host
line, which goes through the least arrival lags, would come out a tick early. So between two
/clock messages the arrival clock moves on with the steady clock at the pace /clock has kept over
the last second (a replay at ``--rate 0.5`` moves half as fast), never past where the next tick is
due (a paused player holds it)."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable

from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from evsync_ros.core.density import TimeArray
from evsync_ros.ros.path import stamp_ns

__all__ = ['ArrivalClock', 'HostStamps', 'Ticks']

CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
"""/clock as rclpy's time source takes it."""
PACE_SPAN_NS = 1_000_000_000
"""The steady time over which the pace of /clock is measured."""
FIRST_STEP_NS = 100_000_000
"""How far the clock may move on past a tick before its ticks' step is known."""
STAMPED_NS = 1_000_000_000
"""A stream whose first header.stamp is within this of the host clock is stamped with it."""


class Ticks:
    """/clock messages as they came: the clock's time, between two of them, at a steady time.

    A tick is taken when the executor gets to it, late by however long other callbacks held it:
    the steady time at which the clock read the newest tick is put on the line, at the pace of the
    last ``span_ns``, through the tick taken least late (a late tick would make every arrival after
    it read early, and the host line goes through the earliest). A clock that stood still (a
    paused player) or went back (a loop) measures its pace anew from its first tick moving on; until
    a second one, the pace it had before (at first 1) stands in."""

    def __init__(self, *, span_ns: int = PACE_SPAN_NS) -> None:
        self.span_ns = span_ns
        self._recent: deque[tuple[int, int]] = deque()
        self._pace, self._step = 1.0, FIRST_STEP_NS
        self._stood = False
        self.sure = False
        self._last: tuple[int, int, float, int] | None = None
        """(clock time, steady time it stood there from, pace, a tick's clock step) of the newest tick."""

    def add(self, clock_ns: int, steady_ns: int) -> None:
        """A /clock message of ``clock_ns`` taken at ``steady_ns``."""
        recent = self._recent
        still = bool(recent) and clock_ns <= recent[-1][0]
        if still or self._stood:  # standing, back, or moving again: the pace starts over from here
            recent.clear()
        self._stood = still
        recent.append((clock_ns, steady_ns))
        while len(recent) > 2 and steady_ns - recent[0][1] > self.span_ns:
            recent.popleft()
        first_clock, first_steady = recent[0]
        if len(recent) > 1 and steady_ns > first_steady:
            self._pace = (clock_ns - first_clock) / (steady_ns - first_steady)
            self._step = (clock_ns - first_clock) // (len(recent) - 1)
        pace = 0.0 if still else self._pace
        since = min(s - (c - clock_ns) / pace for c, s in recent) if pace > 0 else steady_ns
        self._last = (clock_ns, round(since), pace, self._step)
        self.sure = len(recent) > 1
        """Whether the pace is measured since the clock last stood still (not only assumed)."""

    def now(self, steady_ns: int) -> int | None:
        """The clock's time at ``steady_ns`` (None before the first tick): never before the newest
        tick, nor past where the next is due."""
        if self._last is None:
            return None
        clock_ns, since, pace, step = self._last
        return clock_ns + min(max(round((steady_ns - since) * pace), 0), step)


class ArrivalClock:
    """The node's ROS clock in ns, as messages arrive (module notes); call it for the time."""

    def __init__(self, node: Node) -> None:
        self._node = node
        self._ros = node.get_clock()
        self.ticks = Ticks()
        self._sim = False
        self._subscribed = False
        self._sim_time(bool(node.get_parameter('use_sim_time').value))
        node.add_post_set_parameters_callback(self._follow)

    def __call__(self) -> int:
        if not self._sim:
            return time.time_ns()
        now = self.ticks.now(time.monotonic_ns())
        return self._ros.now().nanoseconds if now is None else now

    def sure(self) -> bool:
        """Whether a time read now is as good as the clock gets (on sim time: /clock's pace measured)."""
        return not self._sim or self.ticks.sure

    def _follow(self, params: list[Parameter]) -> None:
        for p in params:
            if p.name == 'use_sim_time':
                self._sim_time(bool(p.value))

    def _sim_time(self, on: bool) -> None:
        self._sim = on
        if on and not self._subscribed:
            self._node.create_subscription(Clock, '/clock', self._on_clock, CLOCK_QOS)
            self._subscribed = True

    def _on_clock(self, msg: Clock) -> None:
        self.ticks.add(msg.clock.sec * 1_000_000_000 + msg.clock.nanosec, time.monotonic_ns())


class HostStamps:
    """``reference: host``: when the host had a message, as (event time, host time): its
    header.stamp against its first event where the driver stamps with the host clock (within 1 s of
    it at the stream's first message), else the host clock now against its last event, as
    ``evsync estimate --reference host`` takes the record time; None while the clock is not ``sure``
    (a guess at the host time is no evidence of it: the line goes through the least lags)."""

    def __init__(self, clock: Callable[[], int], *, sure: Callable[[], bool] = lambda: True) -> None:
        self.clock = clock
        self.sure = sure
        self._stamped: dict[str, bool] = {}

    def pair(self, topic: str, times: TimeArray, raw: bytes) -> tuple[int, int] | None:
        now = self.clock()
        stamp = stamp_ns(raw[4:12])
        stamped = self._stamped.setdefault(topic, abs(stamp - now) < STAMPED_NS)
        if stamped:
            return int(times[0]), stamp
        return (int(times[-1]), now) if self.sure() else None
