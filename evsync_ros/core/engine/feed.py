"""One message into the engine (its events and when it arrived): the arrival-lag line judges it (a late
message, far events, a clock jump), its events are binned. Called under the engine's lock, for every
message: scalar tests first, numpy only where a message needs it. numpy only."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.counts import MessageBins
from evsync_ros.core.density import TimeArray
from evsync_ros.core.engine.lock import State
from evsync_ros.core.engine.stream import CameraStream

if TYPE_CHECKING:
    from evsync_ros.core.engine.engine import Engine

__all__ = ['add_bins', 'add_counted', 'add_edges', 'add_times']


def add_edges(e: Engine, topic: str, t: TimeArray, value: np.ndarray) -> None:
    """A message's trigger edges on the shared pulse's channel (times on the stream's timeline, values
    1 rising, 0 falling): the strongest evidence of its line once its density decision picks the pulse
    (``triggers.by_edges``). StreamError for a topic not tracked. Takes the engine's lock."""
    s = e.stream(topic)
    with e.lock:
        s.edges.add(np.asarray(t, np.int64), np.asarray(value, np.uint8))


def add_times(e: Engine, s: CameraStream, times: TimeArray, receipt_ns: int | None, lo: int | None,
              hi: int | None) -> bool:
    """``Engine.add`` of one message's times: False when it showed a clock jump."""
    if not _arrived(e, s, receipt_ns, times.size):
        return True
    if lo is None or hi is None:
        lo, hi = int(times.min()), int(times.max())
    jumped = False
    if receipt_ns is not None:
        jumped, floor, ceiling = _lag(e, s, receipt_ns, int(times[-1]))
        if lo < floor or hi > ceiling:  # (two scalar tests: this runs for every message)
            times, lo, hi = _not_far(s, times, floor, ceiling)
    if times.size:
        _start(e, s, lo)
        s.bins.add(times, lo=lo, hi=hi)
        _binned(e, s, times.size, hi, receipt_ns)
    return not jumped


def add_counted(e: Engine, topic: str, times: TimeArray, receipt_ns: int, *, lo: int, hi: int, mid: int,
                k0: int, counts: np.ndarray) -> bool:
    """``Engine.add`` of a message also counted on the engine's grid (bins ``k0``, ``k0 + 1`` ... from
    time 0 in ``counts``; ``lo``, ``hi``, ``mid``: its least, greatest and middle time), the counts
    taken where its times would be binned as they are (none far: ``BinnedStream.add_counts``): the
    same evidence either way. StreamError for a topic not tracked. Takes the engine's lock."""
    s = e.stream(topic)
    with e.lock:
        return _add_counted(e, s, times, receipt_ns, lo=lo, hi=hi, mid=mid, k0=k0, counts=counts)


def _add_counted(e: Engine, s: CameraStream, times: TimeArray, receipt_ns: int, *, lo: int, hi: int, mid: int,
                 k0: int, counts: np.ndarray) -> bool:
    if not _arrived(e, s, receipt_ns, times.size):
        return True
    jumped, floor, ceiling = _lag(e, s, receipt_ns, int(times[-1]))
    whole = lo >= floor and hi <= ceiling
    if not whole:
        times, lo, hi = _not_far(s, times, floor, ceiling)
    if times.size:
        _start(e, s, lo)
        if not (whole and s.bins.add_counts(k0, counts, n=times.size, lo=lo, hi=hi, mid=mid)):
            s.bins.add(times, lo=lo, hi=hi)
        _binned(e, s, times.size, hi, receipt_ns)
    return not jumped


def _not_far(s: CameraStream, times: TimeArray, floor: int, ceiling: int) -> tuple[TimeArray, int, int]:
    """A message's times within its arrival lag's ``floor`` and ``ceiling`` (the far ones counted),
    their least and greatest (0, 0: none left)."""
    far = (times < floor) | (times > ceiling)
    s.far_events += int(far.sum())
    times = times[~far]
    return (times, int(times.min()), int(times.max())) if times.size else (times, 0, 0)


def _binned(e: Engine, s: CameraStream, n: int, hi: int, receipt_ns: int | None) -> None:
    s.events += n
    if receipt_ns is not None:
        e.envelope.add(s.topic, hi, receipt_ns)


def add_bins(e: Engine, s: CameraStream, m: MessageBins) -> bool:
    """``Engine.add_bins`` of one message already counted on the grid: far events judged by their bin."""
    if not _arrived(e, s, m.receipt_ns, m.events):
        return True
    jumped, floor, ceiling = _lag(e, s, m.receipt_ns, m.hi_ns)
    bins, counts, lo, hi = m.bins, m.counts, m.lo_ns, m.hi_ns
    if lo < floor or hi > ceiling:
        g = e.params.grid_ns
        starts = bins * g
        near = (starts + g > floor) & (starts <= ceiling)
        s.far_events += int(counts[~near].sum())
        bins, counts = bins[near], counts[near]
        if bins.size:
            lo, hi = max(lo, int(bins[0]) * g), min(hi, int(bins[-1] + 1) * g - 1)
    if bins.size:
        _start(e, s, lo)
        s.bins.add_bins(bins, counts, lo=lo, hi=hi, mid=min(max(m.mid_ns, lo), hi))
        s.events += int(counts.sum())
        e.envelope.add(s.topic, hi, m.receipt_ns)
    return not jumped


def _arrived(e: Engine, s: CameraStream, receipt_ns: int | None, events: int) -> bool:
    """A message arrived (silence ends); False when it has no events."""
    if receipt_ns is not None:
        s.resumed = s.last_receipt is not None and receipt_ns - s.last_receipt > e.params.silence_ns
        s.last_receipt = receipt_ns
        s.arrivals += 1
    s.silent = False
    if s.lock.state is State.LOST and e.method.ended(s.topic):  # lost only by silence: its loop has ended
        s.lock.state, s.lock.message = State.LOCKED, 'locked; back from a silence'
    return events > 0


def _lag(e: Engine, s: CameraStream, receipt_ns: int, mid_ns: int) -> tuple[bool, int, int]:
    """Judge a message's arrival lag (``arrival.ArrivalTrack``): whether the clock jumped, and the
    least and greatest event time that are not far."""
    verdict = s.arrival.add(receipt_ns, mid_ns)
    s.late += verdict.late
    if verdict.jumped_ns is not None:
        s.jumps_seen.append((receipt_ns, mid_ns - (s.first_ns or mid_ns), -verdict.jumped_ns))
        _jump(e, s, verdict.jumped_ns)
    if s.topic == e.reference:
        if s.lock.state is not State.LOCKED:  # back from a silence: the reference is its own timeline
            s.lock.state, s.lock.message = State.LOCKED, 'reference'
    elif s.lock.state is State.WAITING:
        s.lock.state, s.lock.message = State.ESTIMATING, 'estimating: waiting for whole windows'
    return verdict.jumped_ns is not None, verdict.floor_ns, verdict.ceiling_ns


def _start(e: Engine, s: CameraStream, lo: int) -> None:
    """The stream's windows begin after a silence (or at its first event); one grid for all."""
    if s.resumed or s.since_ns is None:
        s.since_ns = lo
    if s.first_ns is None:
        s.first_ns = lo
    if s.bins.origin_ns is None:
        s.bins.origin_ns = lo - lo % e.params.grid_ns
    if s.topic != e.reference and s.lock.state is State.WAITING:
        s.lock.state, s.lock.message = State.ESTIMATING, 'estimating: waiting for whole windows'


def _jump(e: Engine, s: CameraStream, by_ns: int) -> None:
    """The stream's clock jumped: it starts over (the reference's: every camera re-acquires)."""
    s.jumps += 1
    e.note_peak()  # the stream's bins are about to go
    what = f'clock jump of {-by_ns / 1e9:+.3f} s in arrival lag'
    if s.topic == e.reference:
        e.forget(s, State.LOCKED, f'{what}; every camera re-acquires', reset=True)
        s.lock.correction = ClockCorrection(offset_ns=0)
        for other in e.cameras:
            e.forget(other, State.WAITING if other.lock.state is State.WAITING else State.ESTIMATING,
                     f'the reference ({e.reference}) jumped; re-acquiring')
    else:
        e.forget(s, State.ESTIMATING, f'{what}; re-acquiring', reset=True)
    s.lock.note = what
