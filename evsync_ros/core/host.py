"""A rig on host time: each camera's map onto the host's (ROS) clock, for fusing with LiDARs and IMUs
that are stamped with it.

The density offsets put every camera on one camera's timeline to microseconds; what host time a rig
instant is comes only from when messages reached the host, which lags the events by a transport
latency of a fraction of a millisecond to several, jittering. Every camera's messages speak to the
same line (the rig timeline against the host clock), so they are pooled: per segment of the rig
timeline (``SEGMENT_NS``) the least (host time - event time) of any camera's message is the
latency floor plus the host's offset there; a line through those minima (offset and drift against
the host), with the segments far above it dropped, is the map. What remains unknown is the floor
itself, the least latency of the fastest camera's path (USB, driver, DDS): host times come out late
by it, a constant that no arrival time can tell apart from an offset (``floor_ns`` takes it out
when known). ``residual_ns`` says how far the minima scatter about the line.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.errors import StreamError

HOST = 'host'
"""The reference name that puts a rig on host time."""
SEGMENT_NS = 250_000_000
"""Rig time per envelope point: long enough that some message of it had a short path."""
MIN_SEGMENTS = 8
"""Fewer segments than this (2 s of recording) give no host fit."""
JUMP_NS = 10_000_000
"""A camera's least arrival lag that steps by more than this, against the reference's, is a clock
that jumped (``lag_jumps``): far beyond the jitter of a quarter second's fastest message."""
JUMP_SEGMENTS = 8
"""Segments either side of a step whose medians are compared (2 s)."""


@dataclass
class HostEnvelope:
    """Per camera, the least (host time - event time) seen in each segment of its own timeline,
    and the event time where it was seen: memory per second of recording, not per message."""

    segment_ns: int = SEGMENT_NS
    _least: dict[str, dict[int, tuple[int, int]]] = field(default_factory=dict)

    def add(self, topic: str, event_ns: int, host_ns: int) -> None:
        """One message: an event time of it (camera timeline) and when the host had it."""
        d = host_ns - event_ns
        seg = event_ns // self.segment_ns
        per = self._least.setdefault(topic, {})
        have = per.get(seg)
        if have is None or d < have[0]:
            per[seg] = (d, event_ns)

    def add_many(self, topic: str, event_ns: np.ndarray, host_ns: np.ndarray) -> None:
        """Many messages of ``topic`` at once (as ``add`` one by one)."""
        t = np.asarray(event_ns, np.int64)
        d = np.asarray(host_ns, np.int64) - t
        seg = t // self.segment_ns
        order = np.lexsort((d, seg))
        first = np.ones(order.size, bool)
        first[1:] = seg[order][1:] != seg[order][:-1]
        for s, dd, tt in zip(seg[order][first].tolist(), d[order][first].tolist(), t[order][first].tolist()):
            per = self._least.setdefault(topic, {})
            have = per.get(s)
            if have is None or dd < have[0]:
                per[s] = (dd, tt)

    @property
    def topics(self) -> list[str]:
        return list(self._least)

    def within(self, spans: Mapping[str, tuple[int, int]]) -> HostEnvelope:
        """The envelope of the topics of ``spans`` with only the points seen at event times within
        each one's (first, last): a point outside is a corrupt event time's, not the stream's."""
        kept = {topic: {seg: (d, t) for seg, (d, t) in self._least.get(topic, {}).items() if first <= t <= last}
                for topic, (first, last) in spans.items()}
        return HostEnvelope(self.segment_ns, kept)

    def trim(self, topic: str, before_ns: int) -> None:
        """Let go of ``topic``'s segments before event time ``before_ns`` (memory stays bounded live)."""
        per = self._least.get(topic)
        if per:
            for seg in [k for k in per if (k + 1) * self.segment_ns <= before_ns]:
                del per[seg]

    def points(self, topic: str) -> tuple[np.ndarray, np.ndarray]:
        """(event times, least host - event) of ``topic``'s segments, in time order."""
        per = self._least.get(topic, {})
        keys = sorted(per)
        return (np.array([per[k][1] for k in keys], np.int64), np.array([per[k][0] for k in keys], np.int64))


@dataclass(frozen=True)
class HostFit:
    """The rig timeline's map onto host time: host = t + offset_ns + skew_ppm 1e-6 (t - anchor_ns)."""

    offset_ns: int
    skew_ppm: float
    anchor_ns: int
    residual_ns: float
    """RMS of the segments' least arrival lags about the line (the jitter the line averaged out)."""
    uncertainty_ns: float
    """Standard error of the line at its anchor (the latency floor aside)."""
    segments: int
    """Segments the line was fitted through (after the late ones were dropped)."""
    dropped: int
    """Segments dropped as far above the line (no short path in them)."""

    @property
    def correction(self) -> ClockCorrection:
        return ClockCorrection(offset_ns=self.offset_ns, skew_ppm=self.skew_ppm, anchor_ns=self.anchor_ns)

    def as_json(self) -> dict[str, object]:
        return {'offset_ns': self.offset_ns, 'skew_ppm': self.skew_ppm, 'anchor_ns': self.anchor_ns,
                'residual_ns': round(self.residual_ns), 'uncertainty_ns': round(self.uncertainty_ns),
                'segments': self.segments, 'dropped': self.dropped}


def fit_host(envelope: HostEnvelope, corrections: Mapping[str, ClockCorrection], *, floor_ns: int = 0,
             segment_ns: int = SEGMENT_NS) -> HostFit:
    """The host map of the rig whose cameras' corrections onto one timeline are ``corrections``
    (cameras without one are left out), from ``envelope``; ``floor_ns``: the known least latency,
    taken out. StreamError when fewer than ``MIN_SEGMENTS`` segments of the rig have a message."""
    ts, ds = [], []
    for topic in envelope.topics:
        c = corrections.get(topic)
        if c is None:
            continue
        t_cam, d_cam = envelope.points(topic)
        t_rig = c.apply(t_cam)
        ts.append(t_rig)
        ds.append(d_cam - (t_rig - t_cam))  # host - rig time
    if not ts:
        raise StreamError('no camera of the host fit has both a correction and messages')
    t, d = np.concatenate(ts), np.concatenate(ds)
    seg = t // segment_ns
    order = np.lexsort((d, seg))
    first = np.ones(order.size, bool)
    first[1:] = seg[order][1:] != seg[order][:-1]
    t, d = t[order][first], d[order][first]  # per rig segment, the least over every camera
    if t.size < MIN_SEGMENTS:
        raise StreamError(f'messages in only {t.size} stretches of {segment_ns / 1e9:g} s: putting the rig on the '
                          f'host clock needs messages in {MIN_SEGMENTS} ({MIN_SEGMENTS * segment_ns / 1e9:g} s of '
                          'recording)')
    anchor = int(t[t.size // 2])
    x = (t - anchor).astype(np.float64) * 1e-9
    y = (d - d.min()).astype(np.float64)
    keep = np.ones(t.size, bool)
    for _ in range(5):  # a segment whose every message came late lies above the line: drop, refit
        a, b = _line(x[keep], y[keep])
        r = y - (a + b * x)
        spread = 1.4826 * float(np.median(np.abs(r[keep] - np.median(r[keep])))) + 1.0
        new = r < 3 * spread
        if new.sum() < MIN_SEGMENTS or np.array_equal(new, keep):
            break
        keep = new
    a, b = _line(x[keep], y[keep])
    r = (y - (a + b * x))[keep]
    n = int(keep.sum())
    rms = float(np.sqrt(np.mean(r ** 2)))
    se = rms / math.sqrt(n) if n > 2 else math.inf
    offset = int(round(a + float(d.min()))) - floor_ns
    return HostFit(offset_ns=offset, skew_ppm=b * 1e-3, anchor_ns=anchor, residual_ns=rms, uncertainty_ns=se,
                   segments=n, dropped=int(t.size - n))


def arrival_offsets_ns(envelope: HostEnvelope, reference: str) -> dict[str, int]:
    """Per camera, its offset onto ``reference``'s timeline as the host's arrival times give it: the
    median of its segments' least (host time - event time) less the reference's. Good to the
    difference of the two paths' latencies and what the cameras drift against the host between the
    stretches each covers (milliseconds), whatever the clocks read and whenever each camera began:
    where a search is centred (the live node's priors are the same lags, ``online``). Cameras
    without a message are left out, and all are when the reference has none."""
    _, least_ref = envelope.points(reference)
    if least_ref.size == 0:
        return {}
    base = float(np.median(least_ref))
    out = {}
    for topic in envelope.topics:
        _, least = envelope.points(topic)
        if topic != reference and least.size:
            out[topic] = int(round(float(np.median(least)) - base))
    return out


def lag_jumps(t_ns: np.ndarray, lag_ns: np.ndarray, *, min_ns: int = JUMP_NS, side: int = JUMP_SEGMENTS
              ) -> list[tuple[int, int]]:
    """(time, size) of each jump in a series of least arrival lags (``HostEnvelope.points``, or such a
    series less another camera's): where the median of the next ``side`` points leaves the median of
    the last ``side`` by more than ``min_ns``, at the point of the largest such step around it. A
    clock that runs fast or slow moves the lag by its skew only (100 ppm: 0.2 ms over the 2 s either
    side), and a segment whose every message came late is outvoted by the others."""
    if lag_ns.size < 2 * side:
        return []
    step = median_steps(lag_ns, side)
    out = []
    k = 0
    while k < step.size:
        if abs(step[k]) <= min_ns:
            k += 1
            continue
        end = k
        while end + 1 < step.size and abs(step[end + 1]) > min_ns and np.sign(step[end + 1]) == np.sign(step[k]):
            end += 1
        best = k + int(np.argmax(np.abs(step[k:end + 1])))
        out.append((int(t_ns[best + side]), int(round(step[best]))))
        k = end + 1
    return out


def median_steps(lag_ns: np.ndarray, side: int) -> np.ndarray:
    """At each point k from ``side`` to ``size - side``: the median of the ``side`` points from k less
    the median of the ``side`` before it (every window's median in one numpy call)."""
    middle = np.median(np.lib.stride_tricks.sliding_window_view(lag_ns.astype(np.float64), side), axis=1)
    return middle[side:] - middle[:-side]


def _line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares (intercept, slope) of y on x (slope 0 for a single x)."""
    if x.size < 2 or float(np.ptp(x)) == 0.0:
        return float(np.mean(y)), 0.0
    b, a = np.polyfit(x, y, 1)
    return float(a), float(b)


class HostTracker:
    """The live form: a ``HostEnvelope`` fed from the message threads and fitted from the estimator's,
    over the newest ``span_ns`` of the rig timeline (older segments are let go: memory stays bounded)."""

    def __init__(self, *, span_ns: int, segment_ns: int = SEGMENT_NS, floor_ns: int = 0) -> None:
        self.span_ns = span_ns
        self.floor_ns = floor_ns
        self._env = HostEnvelope(segment_ns)
        self._lock = threading.Lock()
        self._newest: dict[str, int] = {}

    def add(self, topic: str, event_ns: int, host_ns: int) -> None:
        """One message (any thread)."""
        with self._lock:
            self._env.add(topic, event_ns, host_ns)
            self._newest[topic] = max(self._newest.get(topic, event_ns), event_ns)

    def prior(self, topic: str) -> int | None:
        """The least (host - event) of ``topic`` so far in its newest segments: its map onto host time
        before any fit, good to the jitter (None before its first message)."""
        with self._lock:
            _, d = self._env.points(topic)
            return int(d[-8:].min()) if d.size else None

    def fit(self, corrections: Mapping[str, ClockCorrection]) -> HostFit:
        """The host line over the newest span (StreamError: not enough yet)."""
        with self._lock:
            for topic, newest in self._newest.items():
                per = self._env._least.get(topic, {})
                old = [k for k in per if k < (newest - self.span_ns) // self._env.segment_ns]
                for k in old:
                    del per[k]
            env = HostEnvelope(self._env.segment_ns, {t: dict(p) for t, p in self._env._least.items()})
        return fit_host(env, corrections, floor_ns=self.floor_ns, segment_ns=env.segment_ns)


def clock_jumps(arrivals: HostEnvelope, reference: str) -> dict[str, tuple[int, int]]:
    """Per camera of ``arrivals`` whose clock jumped against the reference's during the recording:
    where (on its own timeline) and by how much (ns) it jumped first, from its least arrival lags
    less the reference's at the same host time (``lag_jumps``). Matched by host time, the
    estimate is not needed, and a jump of the host's clock moves both lags alike: no camera's jump.
    A jump of the reference's clock is every camera's. ``arrivals`` should hold no lag seen at a
    corrupt event time (``HostEnvelope.within``)."""
    t_ref, lag_ref = arrivals.points(reference)
    out: dict[str, tuple[int, int]] = {}
    if t_ref.size == 0:
        return out
    host_ref = (t_ref + lag_ref).astype(np.float64)
    order = np.argsort(host_ref, kind='stable')
    host_ref, lag_ref_f = host_ref[order], lag_ref[order].astype(np.float64)
    for topic in arrivals.topics:
        t, lag = arrivals.points(topic)
        if topic == reference or t.size == 0:
            continue
        relative = lag - np.interp((t + lag).astype(np.float64), host_ref, lag_ref_f)
        found = lag_jumps(t, np.rint(relative).astype(np.int64))
        if found:
            at, step = found[0]
            out[topic] = (at, -step)  # the lag falls as the clock reads more
    return out
