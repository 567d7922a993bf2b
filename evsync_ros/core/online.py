"""Online synchronisation: every camera's offset tracked while its events arrive (the live node's core).
numpy only. A front end calls ``add`` per message, ``step`` from a timer, and restamps with
``correction``. How it works (arrival-time priors, windows, states): docs/method.md, "Live"."""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np

from evsync_ros.core.bins import BinnedStream, GridCounts
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.density import TimeArray, check_positive_int
from evsync_ros.core.errors import ParameterError, StreamError
from evsync_ros.core.paper import PaperParams, estimate_window_counts
from evsync_ros.core.refined import MIN_DRIFT_WINDOWS, SKEW_SIGNIFICANCE, RefinedParams, fit_line, fit_window
from evsync_ros.core.results import METHODS, latency_deltas

LATENCY_LIMIT_NS = 1_000_000_000
"""A known envelope latency is a camera's response time: a second or more is a mistake."""


EARLY_DRIFT_WINDOWS = 3
"""With the refined method, the tracked line gets a slope from this many accepted windows on (the
batch estimate waits for ``refined.MIN_DRIFT_WINDOWS``, which its robust fit needs). A live
correction restamps the messages arriving now, half a window and more past the newest window's
centre: a camera whose clock runs 50 ppm fast is 0.4 ms off there while its skew is left at 0,
and a slope from three windows whose offsets scatter by tens of microseconds is a few ppm off.
The slope is kept when it is ``SKEW_SIGNIFICANCE`` standard errors from zero, as always. The
paper's method (windows good to milliseconds) waits for ``MIN_DRIFT_WINDOWS``.
``studies/online_drift.py`` measures the live error before and after the line has its full span."""


class State(str, Enum):
    WAITING = 'waiting'
    ESTIMATING = 'estimating'
    LOCKED = 'locked'
    LOST = 'lost'


@dataclass(frozen=True)
class OnlineParams:
    """What the online estimate needs beyond the estimator's own parameters."""

    method: str = 'refined'
    refined: RefinedParams = RefinedParams(max_shift_ns=500_000_000)
    """The refined estimator; its ``max_shift_ns`` is the search half-range around the prior."""
    paper: PaperParams = PaperParams()
    hop_ns: int = 5_000_000_000
    """Least time between two windows of one camera."""
    drift_span_ns: int = 60_000_000_000
    """Accepted windows that started within this span of the newest make the tracked line."""
    silence_ns: int = 2_000_000_000
    """A stream with no message for this long (arrival clock) is silent."""
    jump_ns: int = 1_000_000_000
    """A message whose lag leaves the stream's median lag by more than this is a clock jump."""
    step_ns: int = 10_000_000
    """An accepted window this far from the tracked line is an outlier (two in a row: a step)."""
    lost_after: int = 6
    """Rejected windows in a row after which a locked camera is lost."""
    lag_messages: int = 64
    """Messages whose lags make the median."""

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ParameterError(f'method must be one of {", ".join(METHODS)}, got {self.method!r}')
        for name in ('hop_ns', 'drift_span_ns', 'silence_ns', 'jump_ns', 'step_ns', 'lost_after', 'lag_messages'):
            check_positive_int(getattr(self, name), name=name)

    @property
    def grid_ns(self) -> int:
        return self.refined.fine_ns if self.method == 'refined' else self.paper.tau_ns

    @property
    def window_ns(self) -> int:
        return self.refined.window_ns if self.method == 'refined' else self.paper.window_ns

    @property
    def reach_ns(self) -> int:
        """How far beyond the window a camera's counts are read."""
        if self.method == 'refined':
            return self.refined.camera_reach_ns
        return 0


@dataclass(frozen=True)
class Fit:
    """One window of one camera, in either method's terms."""

    ref_start_ns: int
    offset_ns: int
    accepted: bool
    cost: float
    confidence: float


@dataclass(frozen=True)
class Status:
    """What a front end reports of one stream."""

    topic: str
    state: State
    correction: ClockCorrection | None
    """The correction messages get now (None: not locked since the last jump)."""
    prior_ns: int | None
    """Offset from arrival times alone."""
    cost: float
    confidence: float
    windows_tried: int
    windows_accepted: int
    jumps: int
    events: int
    far_events: int
    """Events not binned: further than jump_ns from where the stream's lag puts them."""
    silent_ns: int | None
    """Time since the stream's last message (arrival clock), None before its first."""
    window_ns: tuple[int, int] | None
    """The last accepted window, reference timeline."""
    message: str
    bins_bytes: int = 0
    """Memory of the stream's density bins (bounded by the span kept: two windows, the reach, a hop)."""


@dataclass
class _Stream:
    topic: str
    grid_ns: int
    lags: deque[int] = field(default_factory=deque)
    median_lag: int | None = None
    bins: BinnedStream = field(init=False)
    last_receipt: int | None = None
    state: State = State.WAITING
    fits: list[Fit] = field(default_factory=list)
    """Accepted windows on the tracked line."""
    outliers: list[Fit] = field(default_factory=list)
    last_fit: Fit | None = None
    last_start: int | None = None
    rejected_in_row: int = 0
    correction: ClockCorrection | None = None
    tried: int = 0
    accepted: int = 0
    jumps: int = 0
    events: int = 0
    far_events: int = 0
    generation: int = 0
    message: str = 'waiting for events'
    resumed_ns: int | None = None
    """First event time after the stream's last silence: windows begin after it (a window across
    the gap would compare events with none)."""

    def forget(self, state: State, message: str) -> None:
        """Drop the estimate (a clock jumped): windows, line, correction; fits under way are stale."""
        self.fits.clear()
        self.outliers.clear()
        self.last_fit = None
        self.last_start = None
        self.rejected_in_row = 0
        self.correction = None
        self.generation += 1
        self.state = state
        self.message = message

    def __post_init__(self) -> None:
        self.bins = BinnedStream(grid_ns=self.grid_ns)

    def reset(self, state: State, message: str) -> None:
        """Start over: the estimate, and the bins and lags of the old clock."""
        self.bins = BinnedStream(grid_ns=self.grid_ns)
        self.resumed_ns = None
        self.lags.clear()
        self.median_lag = None
        self.forget(state, message)


class OnlineSync:
    """Every camera against ``reference``, tracked while events arrive (module notes)."""

    def __init__(self, topics: Iterable[str], *, reference: str, params: OnlineParams = OnlineParams(),
                 latencies_ns: Mapping[str, int] | None = None) -> None:
        topics = list(dict.fromkeys(topics))
        if reference not in topics:
            raise StreamError(f'reference stream {reference!r} is not among {sorted(topics)}')
        if len(topics) < 2:
            raise StreamError('online synchronisation needs the reference and at least one other stream')
        latencies_ns = dict(latencies_ns or {})
        for topic, value in latencies_ns.items():
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or abs(value) > LATENCY_LIMIT_NS:
                raise ParameterError(f'latency of {topic} must be whole nanoseconds within +-1 s, got {value!r}')
        self.latency_delta_ns = latency_deltas(latencies_ns, topics=topics, reference=reference)
        """What each camera's correction gets added: its known latency minus the reference's."""
        if params.hop_ns % params.grid_ns or params.window_ns % params.grid_ns:
            raise ParameterError('hop and window must be whole numbers of the grid')
        self.params = params
        self.reference = reference
        self._lock = threading.Lock()
        self._streams = {t: _Stream(t, params.grid_ns) for t in topics}
        for s in self._streams.values():
            s.reset(State.WAITING, 'waiting for events')
        ref = self._streams[reference]
        ref.correction = ClockCorrection(offset_ns=0)
        g = params.grid_ns
        self._line_params = replace(params.refined, window_ns=params.window_ns, tau_ns=g, fine_ns=g, smooth_ns=g)
        """What refined.fit_line reads: the window (centres) and whether drift is wanted."""
        self._keep_ns = 2 * params.window_ns + 2 * params.reach_ns + params.hop_ns
        """Bins kept behind each stream's newest event, whatever its windows (memory bound)."""

    # -- feeding (any thread) -------------------------------------------------------------------

    def add(self, topic: str, times: TimeArray, receipt_ns: int) -> bool:
        """Bin one message's event times; False when the message showed a clock jump (the stream
        starts over: its messages go out uncorrected until it locks again)."""
        s = self._streams.get(topic)
        if s is None:
            raise StreamError(f'{topic!r} is not a stream of this synchronisation')
        with self._lock:
            resumed = s.last_receipt is not None and receipt_ns - s.last_receipt > self.params.silence_ns
            s.last_receipt = receipt_ns
            if times.size == 0:
                return True
            if resumed:
                s.resumed_ns = int(times.min())
            lag = receipt_ns - int(times[times.size // 2])  # the middle event: one corrupt time moves no lag
            jumped = s.median_lag is not None and abs(lag - s.median_lag) > self.params.jump_ns
            if jumped and s.median_lag is not None:
                self._jump(s, lag - s.median_lag)
            s.lags.append(lag)
            if len(s.lags) > self.params.lag_messages:
                s.lags.popleft()
            if s.median_lag is None or len(s.lags) <= 8:
                s.median_lag = int(np.median(np.fromiter(s.lags, np.int64)))
            if s.topic == self.reference:
                if s.state is not State.LOCKED:
                    s.state, s.message = State.LOCKED, 'reference'
            elif s.state is State.WAITING:
                s.state = State.ESTIMATING
                s.message = 'estimating: waiting for a whole window'
            expected = receipt_ns - s.median_lag
            jump = self.params.jump_ns
            far = (times < expected - jump - self.params.window_ns) | (times > expected + jump)
            if far.any():
                s.far_events += int(far.sum())
                times = times[~far]
            if times.size:
                if s.bins.origin_ns is None:
                    first = int(times.min())
                    s.bins.origin_ns = first - first % self.params.grid_ns  # one grid for every stream
                s.bins.add(times)
                s.events += int(times.size)
            return not jumped

    def _jump(self, s: _Stream, by_ns: int) -> None:
        s.jumps += 1
        what = f'clock jump of {by_ns / 1e9:+.3f} s in arrival lag'
        if s.topic == self.reference:
            s.reset(State.LOCKED, f'{what}; every camera re-acquires')
            s.correction = ClockCorrection(offset_ns=0)
            for other in self._streams.values():
                if other is not s:
                    other.forget(State.WAITING if other.state is State.WAITING else State.ESTIMATING,
                                 f'the reference ({self.reference}) jumped; re-acquiring')
        else:
            s.reset(State.ESTIMATING, f'{what}; re-acquiring')

    # -- estimating (timer thread) --------------------------------------------------------------

    def step(self, now_ns: int) -> int:
        """Fit every window that is ready; returns how many were fitted."""
        jobs: list[tuple[int, _Stream, GridCounts, GridCounts, int, int]] = []
        with self._lock:
            self._medians()
            self._trim()
            self._silence(now_ns)
            ref = self._streams[self.reference]
            for s in self._streams.values():
                if s is ref:
                    continue
                job = self._ready(ref, s)
                if job is not None:
                    jobs.append(job)
        for generation, s, ref_counts, cam_counts, w, prior in jobs:
            fit = self._fit(s, ref_counts, cam_counts, w, prior)
            with self._lock:
                self._record(generation, s, fit)
        return len(jobs)

    def _medians(self) -> None:
        for s in self._streams.values():
            if s.lags:
                s.median_lag = int(np.median(np.fromiter(s.lags, np.int64)))

    def _trim(self) -> None:
        for s in self._streams.values():
            if s.bins.last_ns is not None:
                s.bins.drop_before(s.bins.last_ns - self._keep_ns)

    def _silence(self, now_ns: int) -> None:
        for s in self._streams.values():
            if s.last_receipt is None:
                continue
            quiet = now_ns - s.last_receipt
            if quiet > self.params.silence_ns and s.state is State.LOCKED:
                s.state = State.LOST
                s.message = f'silent for {quiet / 1e9:.1f} s; keeping the last correction'

    def prior(self, topic: str) -> int | None:
        """The offset of ``topic`` from arrival times (reference: 0)."""
        ref, s = self._streams[self.reference], self._streams[topic]
        if ref.median_lag is None or s.median_lag is None:
            return None
        g = self.params.grid_ns
        return int(round((s.median_lag - ref.median_lag) / g)) * g

    def _ready(self, ref: _Stream, s: _Stream) -> tuple[int, _Stream, GridCounts, GridCounts, int, int] | None:
        p = self.params
        ref_last, cam_last = ref.bins.last_ns, s.bins.last_ns
        ref_origin, ref_first, cam_first = ref.bins.origin_ns, ref.bins.first_ns, s.bins.first_ns
        if ref_last is None or cam_last is None or ref_origin is None or ref_first is None or cam_first is None:
            return None
        g, T = p.grid_ns, p.window_ns
        if s.fits:
            centre = self._predict(s, ref_last - T // 2)
            prior = int(round(centre / g)) * g
        else:
            arrival = self.prior(s.topic)
            if arrival is None:
                return None
            prior = arrival
        reach = p.reach_ns
        end = min(ref_last, cam_last + prior - reach)
        w = end - T
        w -= (w - ref_origin) % g
        if w < ref_first or w < cam_first + prior + reach:
            return None
        if (ref.resumed_ns is not None and w < ref.resumed_ns) or \
                (s.resumed_ns is not None and w < s.resumed_ns + prior + reach):
            return None  # the window would span a silence of either stream
        if s.last_start is not None and w < s.last_start + p.hop_ns:
            return None
        ref_counts = ref.bins.snapshot(w, w + T)
        cam_counts = s.bins.snapshot(w - prior - reach - 2 * g, w - prior + T + reach + 2 * g)
        s.last_start = w
        return (s.generation, s, ref_counts, cam_counts, w, prior)

    def _fit(self, s: _Stream, ref_counts: GridCounts, cam_counts: GridCounts, w: int, prior: int) -> Fit:
        p = self.params
        if p.method == 'refined':
            f = fit_window(ref_counts, cam_counts, ref_start_ns=w, prior_ns=prior, params=p.refined)
            cost = 1 - f.peak if not math.isnan(f.peak) else math.inf
            return Fit(w, f.offset_ns, f.accepted, cost, f.confidence)
        n, tau = p.paper.n_bins, p.paper.tau_ns
        r = estimate_window_counts(ref_counts.counts(w, tau, n), cam_counts.counts(w - prior, tau, n),
                                   ref_start_ns=w, cam_start_ns=w - prior, index=s.tried, params=p.paper)
        return Fit(w, r.offset_ns, r.accepted, r.cost, 1.0 if r.accepted else 0.0)

    def _record(self, generation: int, s: _Stream, fit: Fit) -> None:
        if generation != s.generation:
            return  # the stream jumped while its window was fitted: the fit is of a stale clock
        p = self.params
        s.tried += 1
        s.last_fit = fit
        if not fit.accepted:
            s.rejected_in_row += 1
            why = (f'window at {fit.ref_start_ns / 1e9:.1f} s rejected (cost {fit.cost:.3g}, '
                   f'confidence {fit.confidence:.2f})')
            if s.state is State.LOCKED and s.rejected_in_row >= p.lost_after:
                s.state = State.LOST
                s.message = f'{s.rejected_in_row} windows in a row rejected; keeping the last correction'
            elif s.state is State.ESTIMATING:
                s.message = f'estimating: {why}'
            return
        s.rejected_in_row = 0
        s.accepted += 1
        half = p.window_ns // 2
        if s.fits:
            off = fit.offset_ns - self._predict(s, fit.ref_start_ns + half)
            if abs(off) > p.step_ns:
                s.outliers.append(fit)
                pair = s.outliers[-2:]
                if len(pair) < 2 or abs(pair[1].offset_ns - pair[0].offset_ns) > p.step_ns:
                    s.outliers = pair[-1:]
                    s.message = (f'window at {fit.ref_start_ns / 1e9:.1f} s departs from the line by '
                                 f'{off / 1e6:+.3f} ms (outlier)')
                    return
                s.fits = list(pair)
                s.message = f'clock stepped by {off / 1e6:+.3f} ms; tracking from the new offset'
            else:
                s.fits.append(fit)
                s.message = 'locked'
            s.outliers.clear()
        else:
            s.fits.append(fit)
            s.message = 'locked'
        newest = s.fits[-1].ref_start_ns
        s.fits = [f for f in s.fits if f.ref_start_ns >= newest - p.drift_span_ns]
        s.correction = self._line(s.fits)
        s.state = State.LOCKED

    def _line(self, fits: list[Fit]) -> ClockCorrection:
        least = EARLY_DRIFT_WINDOWS if self.params.method == 'refined' else MIN_DRIFT_WINDOWS
        offset, skew, anchor, se = fit_line(fits, self._line_params, min_windows=least)
        if abs(skew) < SKEW_SIGNIFICANCE * se:  # below ``least`` windows the fit gives slope 0, error inf
            skew = 0.0
        return ClockCorrection(offset_ns=offset, skew_ppm=skew, anchor_ns=anchor)

    def _predict(self, s: _Stream, ref_time_ns: int) -> int:
        """The tracked line's offset at a reference time."""
        c = s.correction
        if c is None:
            return 0
        # the line is a function of camera time; camera time ~ ref time - offset
        return c.apply_one(ref_time_ns - c.offset_ns) - (ref_time_ns - c.offset_ns)

    # -- reading (any thread) -------------------------------------------------------------------

    def correction(self, topic: str) -> ClockCorrection | None:
        """The correction a camera's messages get now, its known latency taken out (None: not locked
        since the last jump)."""
        return self._published(self._streams[topic])

    def _published(self, s: _Stream) -> ClockCorrection | None:
        c, delta = s.correction, self.latency_delta_ns[s.topic]
        return replace(c, offset_ns=c.offset_ns + delta) if c is not None and delta else c

    def state(self, topic: str) -> State:
        return self._streams[topic].state

    def status(self, topic: str, now_ns: int | None = None) -> Status:
        with self._lock:
            s = self._streams[topic]
            last = s.last_fit
            good = s.fits[-1] if s.fits else None
            T = self.params.window_ns
            return Status(
                topic=topic, state=s.state, correction=self._published(s),
                prior_ns=0 if topic == self.reference else self.prior(topic),
                cost=last.cost if last else math.nan, confidence=last.confidence if last else math.nan,
                windows_tried=s.tried, windows_accepted=s.accepted, jumps=s.jumps, events=s.events,
                far_events=s.far_events + s.bins.far_events,
                silent_ns=None if s.last_receipt is None or now_ns is None else now_ns - s.last_receipt,
                window_ns=(good.ref_start_ns, good.ref_start_ns + T) if good else None, message=s.message,
                bins_bytes=s.bins.nbytes)

    @property
    def nbytes(self) -> int:
        return sum(s.bins.nbytes for s in self._streams.values())

    def bins_ceiling_bytes(self, step_period_ns: int) -> int:
        """The most every stream's bins can hold together when ``step`` runs every ``step_period_ns``:
        each keeps ``_keep_ns`` behind its newest event, grows by a period between two steps, reaches
        at most ``jump_ns`` past its lag (later times are counted as far), and holds whole blocks."""
        span = self._keep_ns + step_period_ns + self.params.jump_ns
        return len(self._streams) * BinnedStream.ceiling_bytes(span, self.params.grid_ns)
