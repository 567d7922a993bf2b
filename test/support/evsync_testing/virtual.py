"""Virtual rigs cut from one real recording: two cameras whose true offset is known, because both
come from one sensor and one clock (``bench/realrigs.py`` and the trust tests build them here).

A recording's events are split between the two cameras (pixel parity, sensor halves, or a random
half of the pixels); the second camera is then made a coarser, less sensitive camera of another make
if asked (``coarser``), thinned, jittered, given noise or hot pixels, cut (late start, early stop,
gap) and put on its own clock (offset, skew).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from evsync_ros.core.refined import ncc_all_lags

MS = 1_000_000
S = 1_000_000_000


@dataclass(frozen=True)
class Case:
    """One virtual rig: how to cut it from a recording, and what is done to its second camera."""

    group: str
    name: str
    source: str
    split: str = 'parity'
    offset_ns: int = 0
    skew_ppm: float = 0.0
    keep: float = 1.0
    noise: float = 0.0
    """Background events added to the second camera, as a fraction of its own event count."""
    hot: int = 0
    """Hot pixels added to the second camera, each firing at 2 kHz."""
    jitter_ns: int = 0
    late_ns: int = 0
    early_ns: int = 0
    gap: tuple[int, int] | None = None
    """A stretch [start, end) of the second camera's recording, in ns from its start, with no events."""
    cut_ns: int = 0
    """Both cameras cut to this length from the rig's start (0: whole)."""
    step: tuple[int, int] | None = None
    """(at, by): the second camera's clock jumps by ``by`` ns at ``at`` ns from the rig's start (a driver
    restarted, a timestamp reset); the truth is its clock before the jump."""
    pixels: int = 1
    """The second camera's pixels, each ``pixels`` x ``pixels`` of the recording's (``coarser``)."""
    threshold: int = 1
    """The second camera fires once per this many of the recording's events at one of its pixels and
    polarity: a higher contrast threshold (``coarser``)."""
    dead_ns: int = 0
    """The second camera's refractory period: no event within this of the one before at the same
    pixel and polarity (``coarser``)."""
    motion_ns: int = 0
    """The scene moves only this long from the recording's start; after it, a twentieth of its
    events stay (a quiet scene: a rig that stopped moving). 0: the recording as it is."""
    seed: int = 0
    preset: str = ''


QUIET_KEEP = 0.05
"""The share of the recording's events kept after ``Case.motion_ns``."""


def first_camera(x: np.ndarray, y: np.ndarray, how: str, seed: int) -> np.ndarray:
    """Which events the first camera gets (a mask), split ``how`` (``Case.split``)."""
    if how == 'parity':
        return np.asarray((x.astype(np.int64) + y) % 2 == 0)
    if how == 'halves':
        return np.asarray(x < (int(x.max()) + 1) // 2)
    pixels = x.astype(np.int64) * 4096 + y
    keys = np.unique(pixels)
    chosen = np.random.default_rng(seed).random(keys.size) < 0.5
    return np.asarray(chosen[np.searchsorted(keys, pixels)])


def coarser(t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, *, pixels: int = 1, threshold: int = 1,
            dead_ns: int = 0) -> np.ndarray:
    """Which of these events (indices, in time order) a coarser, less sensitive camera of another
    make would give of the same scene: each of its pixels covers ``pixels`` x ``pixels`` of the
    recording's (their events pooled), it fires once per ``threshold`` of the pooled events of one
    polarity (a higher contrast threshold: it fires at the last of them, later on a slow edge), and
    not within ``dead_ns`` of the pooled event before (a refractory period, which drops the rest of
    a burst). Not emulated: a slower photoreceptor's latency, which nothing in event times tells from
    a clock offset (``RigFit.with_latencies``)."""
    group = ((x.astype(np.int64) // pixels) * 65536 + y.astype(np.int64) // pixels) * 2 + (p.astype(np.int64) != 0)
    order = np.lexsort((t, group))
    g, ts = group[order], t[order]
    starts = np.concatenate(([True], g[1:] != g[:-1]))
    idx = np.arange(g.size)
    rank = idx - np.maximum.accumulate(np.where(starts, idx, 0))  # each event's place among its pixel's
    keep = rank % threshold == threshold - 1
    if dead_ns:
        keep &= starts | (ts - np.concatenate(([ts[0]], ts[:-1])) >= dead_ns)
    kept = order[keep]
    return np.asarray(kept[np.argsort(t[kept], kind='stable')])


def cut_index(case: Case, events: tuple[np.ndarray, ...], rng: np.random.Generator
              ) -> tuple[np.ndarray, np.ndarray, int, int]:
    """The events (indices into ``events``) each camera keeps of the recording's: split, the second
    made of another make and thinned (drawing from ``rng``), both cut, each in the recording's order
    (the second's in time order when of another make: what the draws are made in). And the
    recording's span [t0, t1] (as cut)."""
    t, x, y = events[0], events[1], events[2]
    first = first_camera(x, y, case.split, case.seed)
    a, b = np.flatnonzero(first), np.flatnonzero(~first)
    if case.motion_ns:  # drawn from a generator of its own: the other cases' draws stay as they were
        quiet = (t - t[0] >= case.motion_ns) & (np.random.default_rng(case.seed + 1000).random(t.size) >= QUIET_KEEP)
        a, b = a[~quiet[a]], b[~quiet[b]]
    if case.pixels > 1 or case.threshold > 1 or case.dead_ns:
        b = b[coarser(t[b], x[b], y[b], events[3][b], pixels=case.pixels, threshold=case.threshold,
                      dead_ns=case.dead_ns)]
    t0, t1 = int(t[0]), int(t[-1])
    if case.cut_ns:
        a, b = a[t[a] < t0 + case.cut_ns], b[t[b] < t0 + case.cut_ns]
        t1 = min(t1, t0 + case.cut_ns)
    if case.keep < 1:
        b = b[rng.random(b.size) < case.keep]
    return a, b, t0, t1


def recorded(case: Case, times: np.ndarray, *, t0: int, t1: int) -> np.ndarray:
    """Which of the second camera's event ``times`` it recorded: not before its late start, not after
    its early stop, not in its gap."""
    kept = np.ones(times.size, dtype=bool)
    if case.late_ns:
        kept &= times >= t0 + case.late_ns
    if case.early_ns:
        kept &= times < t1 - case.early_ns
    if case.gap:
        kept &= (times < t0 + case.gap[0]) | (times >= t0 + case.gap[1])
    return kept


def second_clock(case: Case, times: np.ndarray, *, t0: int) -> np.ndarray:
    """What the second camera's clock reads (int64 ns) at these instants of the recording: from ``t0``
    on, running ``Case.skew_ppm`` fast, ``Case.offset_ns`` behind."""
    return np.rint((times - t0) * (1 + case.skew_ppm * 1e-6)).astype(np.int64) + t0 - case.offset_ns


def instant_of(case: Case, clock_ns: int, *, t0: int) -> float:
    """The instant of the recording, in ns after ``t0``, at which the second camera's clock reads
    ``clock_ns`` (``second_clock`` undone; after t0, since times near 1e18 ns are 256 ns apart as
    float64)."""
    return (clock_ns - t0 + case.offset_ns) / (1 + case.skew_ppm * 1e-6)


def added_events(case: Case, times: np.ndarray, rng: np.random.Generator, *, t0: int, t1: int
                 ) -> tuple[np.ndarray, list[np.ndarray]]:
    """The second camera's event ``times`` (as ``cut_index`` leaves them) jittered, and the times of
    the events it adds: the background noise's (when ``Case.noise``), then each hot pixel's, drawn
    from ``rng`` after ``cut_index`` in this order (``virtual_rig`` and ``virtualbag`` alike)."""
    if case.jitter_ns:
        times = times + rng.normal(0, case.jitter_ns, times.size).astype(np.int64)
    extra = []
    if case.noise:
        extra.append(rng.integers(t0, t1, int(case.noise * times.size)))
    for _ in range(case.hot):
        n = rng.poisson(2_000 * (t1 - t0) / S)
        extra.append(rng.integers(t0, t1, n))
    return times, extra


def virtual_rig(case: Case, events: tuple[np.ndarray, ...]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """(times per topic, truth in the contract's form) of one array case."""
    times, _, truth = virtual_rig_arriving(case, events)
    return times, truth


ARRIVAL_LAG_NS = 1_000_000
"""When a virtual rig's events reach the host: this long after they happened."""


def virtual_rig_arriving(case: Case, events: tuple[np.ndarray, ...]
                         ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, Any]]:
    """``virtual_rig`` with each event's arrival time on one host clock (the recording's time, plus
    ``ARRIVAL_LAG_NS``): (times per topic, arrival times per topic, truth)."""
    t = events[0]
    rng = np.random.default_rng([case.seed, 7])
    ia, ib, t0, t1 = cut_index(case, events, rng)
    a, b = t[ia], t[ib]
    # the second camera: jittered, noisy, cut, then on its own clock
    b, extra = added_events(case, b, rng, t0=t0, t1=t1)
    if extra:
        b = np.concatenate([b, *extra])
    b = np.sort(b)
    b = b[recorded(case, b, t0=t0, t1=t1)]
    k = case.skew_ppm * 1e-6
    clock = second_clock(case, b, t0=t0)
    if case.step:
        at, by = case.step
        clock = np.where(b >= t0 + at, clock + by, clock)
        order = np.argsort(clock, kind='stable')
        clock, b = clock[order], b[order]
    # truth: reference time = t0 + (c - t0 + offset) / (1 + k); in contract form about the middle
    anchor = int(np.median(clock))
    ref_at_anchor = t0 + instant_of(case, anchor, t0=t0)
    truth = {'offset_ns': int(round(ref_at_anchor - anchor)), 'skew_ppm': (1 / (1 + k) - 1) * 1e6,
             'anchor_ns': anchor}
    return {'/a': a, '/b': clock}, {'/a': a + ARRIVAL_LAG_NS, '/b': b + ARRIVAL_LAG_NS}, truth


def plain_ncc(ref: np.ndarray, cam: np.ndarray, *, search_ns: int = 3 * S) -> int | None:
    """The plain NCC's offset (ns), or None when no lag keeps half the window."""
    tau = MS
    start = int(ref[0])
    n = int(min(10 * S, int(ref[-1]) - start + 1) // tau)
    if n < 2:
        return None
    prior = int(ref[0]) - int(cam[0])
    s = search_ns // tau
    a = np.bincount(((ref - start) // tau)[(ref >= start) & (ref < start + n * tau)], minlength=n)[:n].astype(float)
    cam_start = start - prior - s * tau
    idx = (cam - cam_start) // tau
    b = np.bincount(idx[(idx >= 0) & (idx < n + 2 * s)], minlength=n + 2 * s)[:n + 2 * s].astype(float)
    ncc, count = ncc_all_lags(a, b)
    ncc[count < n / 2] = np.nan
    if np.all(np.isnan(ncc)):
        return None
    m = int(np.nanargmax(ncc))
    frac = 0.0
    if 0 < m < ncc.size - 1 and not np.isnan(ncc[m - 1]) and not np.isnan(ncc[m + 1]):
        y0, y1, y2 = ncc[m - 1], ncc[m], ncc[m + 1]
        if y0 - 2 * y1 + y2 < 0:
            frac = 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)
    return int(round(prior + (s - m - frac) * tau))
