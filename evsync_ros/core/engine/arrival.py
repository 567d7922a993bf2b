"""Arrival lags (arrival minus event time) of one stream, on whatever clock the engine is handed: the
host's, ROS time, sim time, or a bag's record times. numpy only; docs/method.md, "Arrival times".

A stream's lag moves with the pace its messages come at (a bag replayed at 2x loses half a second of
lag a second), so it is followed as a line through its least lag of each ``BUCKET_NS`` of arrivals,
not as a constant: a message is *late* when it lies far above the line, and a *jump* (the camera's
clock stepped) when it lies beyond ``jump_ns`` of it either way. Two streams' lags at one arrival
time differ by their clocks' offset whatever the pace: that is a camera's arrival-time prior, read
from the buckets both streams have (``prior_ns``).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import NamedTuple

__all__ = ['BUCKET_NS', 'LATE_NS', 'ArrivalTrack', 'Verdict', 'prior_ns']

BUCKET_NS = 50_000_000
"""Arrival time per point of the line: the least lag of a bucket is the fast path's, jitter-free."""
BUCKETS = 32
"""Points the line is fitted through (1.6 s of arrivals)."""
MIN_MESSAGES = 8
"""Messages a line needs before a message can leave it by a jump."""
LATE_NS = 50_000_000
"""A message more than this above its stream's line came late: the host fell behind, or the
transport held it. Judged once the line has two points (100 ms of arrivals): before it, a level
would take a slow replay's growing lag for lateness."""


class Verdict(NamedTuple):
    """What one message's lag says (a tuple: one is made per message)."""

    jumped_ns: int | None
    """The message leaves the line by this much (beyond ``jump_ns``): the clock jumped. None: it did not."""
    late: bool
    floor_ns: int
    """The least event time of this message that is not far (a corrupt time), its camera's timeline."""
    ceiling_ns: int
    """The greatest."""


@dataclass
class ArrivalTrack:
    """One stream's lag line (module notes). ``jump_ns``: how far from the line a clock jump is;
    ``reach_ns``: how far before the expected event time events may lie (a window's worth)."""

    jump_ns: int
    reach_ns: int
    base_ns: int | None = None
    """The first lag: every other is held relative to it (a sensor clock near 0 beside host-epoch
    arrivals makes lags of 1e18 ns, beyond a float's exact integers)."""
    last_arrival_ns: int | None = None
    messages: int = 0
    """Messages since the line (re)started: a jump is judged from the ``MIN_MESSAGES``-th on."""
    _points: deque[tuple[int, int]] = field(default_factory=lambda: deque(maxlen=BUCKETS))
    _bucket: int | None = None
    _least: int = 0
    _pending: int | None = None
    """How far the last message left the line, when it did by a jump's size (not yet confirmed)."""
    _least_at: int = 0
    """When the bucket's least lag arrived: the point's place on the line."""
    _line: tuple[float, float, int] = (0.0, 0.0, 0)
    """(lag at ``_line[2]``, slope, arrival origin), relative lags."""
    _newest: tuple[int, int] = (0, 0)
    """The newest message on the line: (arrival, relative lag)."""
    revision: int = 0
    """Moves on whenever the line's points do (a point added, the line restarted)."""
    _paired_with: tuple[ArrivalTrack | None, int, int, int | None] = (None, 0, 0, None)
    """``prior_ns``'s paired reading of this camera: (the reference, both revisions, the reading)."""

    def add(self, arrival_ns: int, event_ns: int) -> Verdict:
        """One message: when it arrived, and its last event's time (the lag is then the path's latency,
        whatever the message's length: cameras sending 1 ms and 10 ms messages compare alike). A
        message that leaves the line by more than ``jump_ns`` is held as a possible jump (a corrupt
        time; its events judged by the line: far); a second one that leaves it alike confirms it,
        and the line starts again from it."""
        lag = arrival_ns - event_ns
        if self.base_ns is None:
            self.base_ns = lag
        rel = lag - self.base_ns
        expected = self.expected(arrival_ns) if self._bucket is not None else rel
        off = int(round(rel - expected))
        self.last_arrival_ns = arrival_ns
        away = abs(off) > self.jump_ns and self.messages >= MIN_MESSAGES
        if away and (self._pending is None or abs(off - self._pending) > self.jump_ns // 2):
            self._pending = off  # one message away: corrupt, or the first of a jump
            return Verdict(jumped_ns=None, late=False, floor_ns=event_ns + off - self.jump_ns - self.reach_ns,
                           ceiling_ns=event_ns + off + self.jump_ns)
        self._pending = None
        lined = len(self._points) >= 2  # what ``expected`` was read from
        if away:
            self.restart()
            self.base_ns = lag
            rel = 0
        self.messages += 1
        self._newest = (arrival_ns, rel)
        self._note(arrival_ns, rel)
        centre = event_ns if away else event_ns + off
        return Verdict(jumped_ns=off if away else None, late=not away and lined and off > LATE_NS,
                       floor_ns=centre - self.jump_ns - self.reach_ns, ceiling_ns=centre + self.jump_ns)

    def _note(self, arrival_ns: int, rel: int) -> None:
        bucket = arrival_ns // BUCKET_NS
        if self._bucket is None or bucket > self._bucket:
            if self._bucket is not None:
                self._points.append((self._least_at, self._least))
                self.revision += 1
            self._bucket, self._least, self._least_at = bucket, rel, arrival_ns
            self._refit()
        elif rel < self._least:
            self._least, self._least_at = rel, arrival_ns

    def _refit(self) -> None:
        """The line through the buckets' least lags: the slope from the medians of the older and the
        newer half (robust to a bucket whose every message came late), the level from the newest."""
        pts = list(self._points)
        if not pts:
            return
        origin = pts[-1][0]
        x = [float(a - origin) for a, _ in pts]  # at most BUCKETS points: plain floats beat numpy here
        y = [float(lag) for _, lag in pts]
        slope = 0.0
        if len(pts) >= 2:
            h = len(pts) // 2
            dx = _median(x[h:]) - _median(x[:h])
            if dx > 0:
                slope = (_median(y[h:]) - _median(y[:h])) / dx
        level = _median([b - slope * a for a, b in zip(x, y)])
        self._line = (level, slope, origin)

    def expected(self, arrival_ns: int) -> float:
        """The stream's relative lag the line gives at ``arrival_ns`` (before it has a slope, its newest
        message's: the pace moves the lag little from one message to the next, a jump at once)."""
        if len(self._points) < 2:
            return float(self._newest[1])
        level, slope, origin = self._line
        return level + slope * (arrival_ns - origin)

    @property
    def slope(self) -> float | None:
        """The line's slope (lag per ns of arrivals: 0 at 1x, -1 at 2x); None before it has two points."""
        return self._line[1] if len(self._points) >= 2 else None

    def lag_at(self, arrival_ns: int, *, slope: float | None = None) -> int | None:
        """The stream's lag (arrival minus event time) the line gives at ``arrival_ns``; None before any.
        Before the line has a slope of its own: its newest message's lag, carried to ``arrival_ns`` at
        ``slope`` (another stream's, at the same pace; None: level)."""
        if self.base_ns is None:
            return None
        lag = self.expected(arrival_ns)
        if self.slope is None and slope is not None:
            lag += slope * (arrival_ns - self._newest[0])
        return self.base_ns + int(round(lag))

    def points(self) -> dict[int, tuple[int, int]]:
        """The line's points by bucket (arrival time // ``BUCKET_NS``): (when the bucket's least lag
        arrived, that lag relative to ``base_ns``)."""
        return {at // BUCKET_NS: (at, lag) for at, lag in self._points}

    def restart(self) -> None:
        """Forget the line (the clock jumped, or the stream starts over)."""
        self.base_ns = None
        self.revision += 1
        self.messages = 0
        self._pending = None
        self._points.clear()
        self._bucket = None
        self._least = 0
        self._line = (0.0, 0.0, 0)


def _median(values: list[float]) -> float:
    """``np.median`` of a few floats, to the bit: the middle one, or the mean of the middle two, summed
    from 0.0 as numpy sums (so a -0.0 comes out 0.0)."""
    s = sorted(values)
    h = len(s) // 2
    return 0.0 + s[h] if len(s) % 2 else (0.0 + s[h - 1] + s[h]) / 2


def prior_ns(camera: ArrivalTrack, reference: ArrivalTrack, *, grid_ns: int) -> int | None:
    """A camera's offset onto the reference's timeline as arrival times give it: the camera's lag less
    the reference's at one arrival time (there the pace cancels), on the grid; None until both have a
    message. Once a bucket of arrivals has passed for both and the pace is known (either line has a
    slope), it is the median over the buckets both lines have of their least lags' difference
    (``_paired``); two lines fitted apart would be refitted at different messages, and on a busy host
    a refit moves a line's reading by tens of milliseconds at 2x. Before that, both lines are read at
    the reference's newest arrival, one without a slope yet at the other's (every stream comes at one
    replay's pace): a bag replayed at 2x loses 50 ms of lag in a bucket, which a level would keep."""
    at = reference.last_arrival_ns
    if at is None or camera.base_ns is None or reference.base_ns is None:
        return None
    offset = _paired(camera, reference, base_ns=camera.base_ns - reference.base_ns)
    if offset is None:
        cam, ref = camera.lag_at(at, slope=reference.slope), reference.lag_at(at, slope=camera.slope)
        assert cam is not None and ref is not None
        offset = cam - ref
    return int(round(offset / grid_ns)) * grid_ns


def _paired(camera: ArrivalTrack, reference: ArrivalTrack, *, base_ns: int) -> int | None:
    """The median over the buckets both lines have a point in of the camera's least lag less the
    reference's, the camera's carried at the pace's slope to when the reference's arrived; None when
    they share no bucket or neither has a slope (``base_ns``: the camera's base lag less the
    reference's). Kept on the camera's track until a point moves."""
    ref_track, rev, ref_rev, cached = camera._paired_with
    if ref_track is reference and rev == camera.revision and ref_rev == reference.revision:
        return cached
    slope = reference.slope if reference.slope is not None else camera.slope
    ref = reference.points()
    value = None
    if slope is not None:
        diffs = [float(lag - ref[b][1]) - slope * (at - ref[b][0]) for b, (at, lag) in camera.points().items()
                 if b in ref]
        value = base_ns + int(round(_median(diffs))) if diffs else None
    camera._paired_with = (reference, camera.revision, reference.revision, value)
    return value
