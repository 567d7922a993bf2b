"""Online synchronisation: every camera's offset tracked while its events arrive (the live node's core).
numpy only. A front end calls ``add`` per message, ``step`` from a timer, and restamps with
``correction``. The refined method uses the bag tools' scheduler, window fits and agreement rule on
the span it keeps, so what is accepted offline is what the node locks on. How it works (arrival-time
priors, windows, states): docs/method.md, "Live".
"""

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
from evsync_ros.core.counts import MessageBins
from evsync_ros.core.density import TimeArray, check_positive_int
from evsync_ros.core.errors import ParameterError, StreamError
from evsync_ros.core.paper import PaperParams, estimate_window_counts
from evsync_ros.core.refined import RefinedParams, camera_result, fit_window
from evsync_ros.core.results import METHODS, CameraFit, WindowFit, latency_deltas
from evsync_ros.core.runner import InThread, Runner
from evsync_ros.core.schedule import plan

LATENCY_LIMIT_NS = 1_000_000_000
"""A known envelope latency is a camera's response time: a second or more is a mistake."""
LATE_NS = 50_000_000
"""A message whose lag (arrival minus event time) exceeds its stream's median by more than this came
late: the host fell behind (or the transport held it)."""


class State(str, Enum):
    """Where a camera's estimate stands."""

    WAITING = 'waiting'
    SEEDED = 'seeded'
    """Corrected with a saved offset (``OnlineSync.seed``) until its own estimate agrees, or replaces it."""
    ESTIMATING = 'estimating'
    LOCKED = 'locked'
    LOST = 'lost'


LIVE_SEARCH_NS = 500_000_000
"""The live search's half-range around the arrival-time prior (the node's ``search_range_s``
default): a prior good to milliseconds needs no more, and a narrow search is less often fooled."""


@dataclass(frozen=True)
class OnlineParams:
    """What the online estimate needs beyond the estimator's own parameters."""

    method: str = 'refined'
    refined: RefinedParams = RefinedParams(max_shift_ns=LIVE_SEARCH_NS)
    """The refined estimator; its ``max_shift_ns`` is the search half-range around the prior."""
    paper: PaperParams = PaperParams()
    hop_ns: int = 5_000_000_000
    """The paper's method: least time between two windows of one camera."""
    drift_span_ns: int = 60_000_000_000
    """Windows that started within this span of the newest make a camera's estimate (the bins of this
    span, and of the search reach, are kept)."""
    silence_ns: int = 2_000_000_000
    """A stream with no message for this long (arrival clock) is silent."""
    jump_ns: int = 1_000_000_000
    """A message whose lag leaves the stream's median lag by more than this is a clock jump."""
    step_ns: int = 10_000_000
    """Windows that depart from the locked line by more than this (and their own errors), agreeing
    among themselves, are a clock step: the estimate starts again from them."""
    lost_after: int = 6
    """The paper's method: rejected windows in a row after which a locked camera is lost."""
    lag_messages: int = 64
    """Messages whose lags make the median."""

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ParameterError(f'method must be one of {", ".join(METHODS)}, got {self.method!r}')
        for name in ('hop_ns', 'drift_span_ns', 'silence_ns', 'jump_ns', 'step_ns', 'lost_after', 'lag_messages'):
            check_positive_int(getattr(self, name), name=name)

    @property
    def grid_ns(self) -> int:
        """The bins every stream is counted in."""
        return self.refined.fine_ns if self.method == 'refined' else self.paper.tau_ns

    @property
    def window_ns(self) -> int:
        """The longest window."""
        return self.refined.window_ns if self.method == 'refined' else self.paper.window_ns

    @property
    def reach_ns(self) -> int:
        """How far beyond the window a camera's counts are read."""
        if self.method == 'refined':
            return self.refined.camera_reach_ns
        return 0


@dataclass(frozen=True)
class Fit:
    """One window of the paper's method."""

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
    """Windows that agree with the accepted line (refined), or windows accepted by epsilon (paper)."""
    jumps: int
    events: int
    far_events: int
    """Events not binned: further than jump_ns from where the stream's lag puts them."""
    silent_ns: int | None
    """Time since the stream's last message (arrival clock), None before its first."""
    window_ns: tuple[int, int] | None
    """The span of the windows behind the correction, reference timeline."""
    message: str
    bins_bytes: int = 0
    """Memory of the stream's density bins (bounded by the span kept)."""
    uncertainty_ns: float | None = None
    """Standard error of the correction's offset (refined)."""
    skew_uncertainty_ppm: float | None = None
    reason: str = ''
    """Why the newest estimate is not accepted ('' when it is)."""
    late_messages: int = 0
    """Messages that arrived more than ``LATE_NS`` after their stream's usual lag."""
    seeds_replaced: int = 0
    """Saved offsets (``seed``) the camera's own estimate disagreed with, and replaced."""
    frozen: bool = False
    """``freeze``: corrections kept, nothing fitted."""


@dataclass
class _Stream:
    topic: str
    grid_ns: int
    lags: deque[int] = field(default_factory=deque)
    median_lag: int | None = None
    bins: BinnedStream = field(init=False)
    last_receipt: int | None = None
    state: State = State.WAITING
    correction: ClockCorrection | None = None
    estimate: CameraFit | None = None
    """The newest refined estimate (accepted or not)."""
    locked_on: CameraFit | None = None
    """The accepted estimate whose correction is in force."""
    fits: dict[tuple[int, int], WindowFit] = field(default_factory=dict)
    """Refined: the windows fitted, by (start, length)."""
    paper_fits: list[Fit] = field(default_factory=list)
    """Paper: accepted windows since the last lock restart."""
    last_fit: Fit | None = None
    last_start: int | None = None
    rejected_in_row: int = 0
    tried: int = 0
    accepted: int = 0
    jumps: int = 0
    events: int = 0
    far_events: int = 0
    late: int = 0
    """Messages that arrived more than LATE_NS after their stream's usual lag (the host fell behind)."""
    generation: int = 0
    message: str = 'waiting for events'
    since_ns: int | None = None
    """Windows begin after this: the stream's first event after its last silence or restart (a
    window across the gap would compare events with none)."""
    resumed: bool = False
    """The last message came after a silence."""
    silent: bool = False
    """No message for ``silence_ns``: its estimate is left as it is until it sends again."""
    note: str = ''
    """What happened to the stream that its next messages should still say (a clock jump)."""
    restart_ns: int | None = None
    """After a clock step, only windows from here on (reference timeline) make the estimate."""
    seeds_replaced: int = 0
    """Saved offsets this stream's own estimate disagreed with, and replaced."""

    def __post_init__(self) -> None:
        self.bins = BinnedStream(grid_ns=self.grid_ns)

    def forget(self, state: State, message: str) -> None:
        """Drop the estimate (a clock jumped): windows, line, correction; fits under way are stale."""
        self.fits.clear()
        self.paper_fits.clear()
        self.restart_ns = None
        self.estimate = None
        self.last_fit = None
        self.last_start = None
        self.rejected_in_row = 0
        self.correction = None
        self.locked_on = None
        self.generation += 1
        self.state = state
        self.message = message

    def reset(self, state: State, message: str) -> None:
        """Start over: the estimate, and the bins and lags of the old clock."""
        self.bins = BinnedStream(grid_ns=self.grid_ns)
        self.since_ns = None
        self.lags.clear()
        self.median_lag = None
        self.forget(state, message)


_Job = tuple[int, _Stream, GridCounts, GridCounts, int, int, int]
"""(generation, stream, reference counts, camera counts, window start, length, prior)."""


@dataclass(frozen=True)
class _Agreeing:
    """A camera's windows to find its estimate from, as they were when taken (``step``)."""

    stream: _Stream
    generation: int
    correction: ClockCorrection | None
    fits: list[WindowFit]
    newest: list[WindowFit] | None
    """Its newest windows, all away from the line in force: a line of their own is a clock step."""


def _fit(params: OnlineParams, ref_counts: GridCounts, cam_counts: GridCounts, w: int, length: int, prior: int,
         tried: int) -> WindowFit | Fit:
    """One window of a camera fitted (``tried``: windows fitted before it, the paper's index)."""
    if params.method == 'refined':
        return fit_window(ref_counts, cam_counts, ref_start_ns=w, length_ns=length, prior_ns=prior,
                          params=params.refined).light()
    n, tau = params.paper.n_bins, params.paper.tau_ns
    r = estimate_window_counts(ref_counts.counts(w, tau, n), cam_counts.counts(w - prior, tau, n),
                               ref_start_ns=w, cam_start_ns=w - prior, index=tried, params=params.paper)
    return Fit(w, r.offset_ns, r.accepted, r.cost, 1.0 if r.accepted else 0.0)


def _agreement(topic: str, fits: list[WindowFit], newest: list[WindowFit] | None, params: RefinedParams
               ) -> tuple[CameraFit, CameraFit | None]:
    """A camera's estimate from its windows, and from its newest ones alone where they are given."""
    return (camera_result(topic, fits, params),
            None if newest is None else camera_result(topic, newest, params))


class OnlineSync:
    """Every camera against ``reference``, tracked while events arrive (module notes).

    Args:
        topics: the streams, the reference among them.
        reference: the stream whose timeline the others join.
        params: the tracking and estimator parameters.
        latencies_ns: known envelope latencies per topic (``results.latency_deltas``), taken out of
            what the front end reads.
        runner: where ``step`` fits the windows and finds the agreement (``core.runner``); the
            calling thread when None. The caller closes it.

    Raises:
        StreamError: the reference is not among the topics, or there is no other.
        ParameterError: a latency is not whole nanoseconds within +-1 s.
    """

    def __init__(self, topics: Iterable[str], *, reference: str, params: OnlineParams = OnlineParams(),
                 latencies_ns: Mapping[str, int] | None = None, runner: Runner | None = None) -> None:
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
        self.runner: Runner = runner if runner is not None else InThread()
        self._lock = threading.Lock()
        self._streams = {t: _Stream(t, params.grid_ns) for t in topics}
        for s in self._streams.values():
            s.reset(State.WAITING, 'waiting for events')
        self._streams[reference].correction = ClockCorrection(offset_ns=0)
        self._keep_ns = params.drift_span_ns + 2 * params.window_ns + 2 * params.reach_ns
        """Bins kept behind each stream's newest event, whatever its windows (memory bound)."""
        self.frozen = False
        """``freeze``: every correction stays as it is; no window is fitted."""

    @property
    def topics(self) -> list[str]:
        """Every stream, the reference among them."""
        return list(self._streams)

    # -- operating (any thread) -----------------------------------------------------------------

    def seed(self, fit: CameraFit) -> None:
        """Correct ``fit.topic`` with a saved estimate (its latency delta included, as ``correction``
        gives it) until its own estimate agrees (then locked) or disagrees (then replaced, and
        counted in ``seeds_replaced``). StreamError for a topic that is not a camera of this rig."""
        if fit.topic not in self._streams or fit.topic == self.reference:
            raise StreamError(f'{fit.topic}: not a camera of this rig to seed (reference {self.reference}, '
                              f'topics {sorted(self._streams)})')
        delta = self.latency_delta_ns[fit.topic]
        with self._lock:
            s = self._streams[fit.topic]
            s.correction = replace(fit.correction, offset_ns=fit.offset_ns - delta)
            s.locked_on = replace(fit, offset_ns=fit.offset_ns - delta)
            s.state = State.SEEDED
            s.message = 'seeded from saved offsets; estimating'

    def retune(self, *, min_confidence: float) -> None:
        """Change the refined estimator's least share of agreeing windows (from the next estimate on);
        ParameterError when it is not in [0, 1]."""
        refined = replace(self.params.refined, min_confidence=min_confidence)
        with self._lock:
            self.params = replace(self.params, refined=refined)

    def freeze(self, on: bool) -> None:
        """Keep every correction as it is and fit nothing (``on``), or go on estimating."""
        with self._lock:
            self.frozen = on

    def reacquire(self) -> None:
        """Forget every camera's estimate and correction and estimate again from the bins held (a
        freeze ends too)."""
        with self._lock:
            self.frozen = False
            for s in self._streams.values():
                if s.topic != self.reference:
                    s.forget(State.WAITING if s.bins.last_ns is None else State.ESTIMATING, 'reacquiring on request')

    def saved(self) -> dict[str, CameraFit]:
        """The estimate in force of each camera that has one (its latency delta included), and the
        reference's entry: what ``results.RigFit`` writes for a later ``seed``."""
        with self._lock:
            ref = self._streams[self.reference]
            out = {self.reference: CameraFit.reference_entry(self.reference, start_ns=ref.bins.origin_ns or 0,
                                                             window_ns=self.params.window_ns)}
            for s in self._streams.values():
                c = s.correction
                if s.topic == self.reference or c is None:
                    continue
                fit = s.locked_on
                if fit is None or fit.correction != c:  # the paper's lock: a correction, no CameraFit
                    fit = CameraFit(topic=s.topic, offset_ns=c.offset_ns, skew_ppm=c.skew_ppm, anchor_ns=c.anchor_ns,
                                    accepted=True, cost=math.nan, confidence=math.nan, window_ns=(0, 0))
                out[s.topic] = replace(fit, offset_ns=fit.offset_ns + self.latency_delta_ns[s.topic])
            return out

    # -- feeding (any thread) -------------------------------------------------------------------

    def add(self, topic: str, times: TimeArray, receipt_ns: int) -> bool:
        """Bin one message's event times (``receipt_ns``: when it arrived, on one monotonic clock of
        the host); False when the message showed a clock jump (the stream starts over: its messages
        go out uncorrected until it locks again). StreamError for a topic not tracked."""
        s = self._stream(topic)
        with self._lock:
            if not self._arrived(s, receipt_ns, times.size):
                return True
            jumped, floor, ceiling = self._lag(s, receipt_ns, int(times[times.size // 2]))
            lo, hi = int(times.min()), int(times.max())
            if lo < floor or hi > ceiling:  # (two scalar tests: this runs for every message)
                far = (times < floor) | (times > ceiling)
                s.far_events += int(far.sum())
                times = times[~far]
                if times.size:
                    lo, hi = int(times.min()), int(times.max())
            if times.size:
                self._start(s, lo, receipt_ns)
                s.bins.add(times, lo=lo, hi=hi)
                s.events += int(times.size)
            return not jumped

    def add_bins(self, topic: str, m: MessageBins) -> bool:
        """``add`` for a message already counted on this synchronisation's grid (``MessageBins.of``
        with ``params.grid_ns``: what a camera process sends). Far events are judged by their bin."""
        s = self._stream(topic)
        with self._lock:
            if not self._arrived(s, m.receipt_ns, m.events):
                return True
            jumped, floor, ceiling = self._lag(s, m.receipt_ns, m.mid_ns)
            bins, counts, lo, hi = m.bins, m.counts, m.lo_ns, m.hi_ns
            if lo < floor or hi > ceiling:
                starts = bins * self.params.grid_ns
                near = (starts + self.params.grid_ns > floor) & (starts <= ceiling)
                s.far_events += int(counts[~near].sum())
                bins, counts = bins[near], counts[near]
                if bins.size:
                    lo = max(lo, int(bins[0]) * self.params.grid_ns)
                    hi = min(hi, int(bins[-1] + 1) * self.params.grid_ns - 1)
            if bins.size:
                self._start(s, lo, m.receipt_ns)
                s.bins.add_bins(bins, counts, lo=lo, hi=hi, mid=min(max(m.mid_ns, lo), hi))
                s.events += int(counts.sum())
            return not jumped

    def _stream(self, topic: str) -> _Stream:
        s = self._streams.get(topic)
        if s is None:
            raise StreamError(f'{topic!r} is not a stream of this synchronisation')
        return s

    def _arrived(self, s: _Stream, receipt_ns: int, events: int) -> bool:
        """A message arrived (silence ends); False when it has no events."""
        s.resumed = s.last_receipt is not None and receipt_ns - s.last_receipt > self.params.silence_ns
        s.last_receipt = receipt_ns
        s.silent = False
        return events > 0

    def _lag(self, s: _Stream, receipt_ns: int, mid_ns: int) -> tuple[bool, int, int]:
        """Judge a message's arrival lag (from its middle event: one corrupt time moves no lag):
        (whether the clock jumped, and the least and greatest event time that are not far)."""
        lag = receipt_ns - mid_ns
        jumped = s.median_lag is not None and abs(lag - s.median_lag) > self.params.jump_ns
        if s.median_lag is not None and not jumped and lag - s.median_lag > LATE_NS:
            s.late += 1
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
            s.message = 'estimating: waiting for whole windows'
        expected = receipt_ns - s.median_lag
        jump = self.params.jump_ns
        return jumped, expected - jump - self.params.window_ns, expected + jump

    def _start(self, s: _Stream, lo: int, receipt_ns: int) -> None:
        """The stream's windows begin after a silence (or at its first event); one grid for all."""
        if s.resumed or s.since_ns is None:
            s.since_ns = lo
        if s.bins.origin_ns is None:
            s.bins.origin_ns = lo - lo % self.params.grid_ns

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
        s.note = what

    # -- estimating (timer thread) --------------------------------------------------------------

    def step(self, now_ns: int) -> int:
        """Fit every window that is ready and update each camera's estimate; returns how many
        windows were fitted. Counts are copied under the lock, and the windows fitted and their
        agreement found outside it, by the runner (module notes), so that ``add`` (another thread)
        waits only for the copies and for the estimates to be put in place."""
        jobs: list[_Job] = []
        with self._lock:
            self._medians()
            self._trim()
            self._silence(now_ns)
            if self.frozen:  # the corrections in force stay; the bins go on (memory), nothing is fitted
                return 0
            params = self.params
            ref = self._streams[self.reference]
            for s in self._streams.values():
                if s is not ref:
                    jobs += self._ready(ref, s)
        fitted = self.runner.run(_fit, [(params, rc, cc, w, length, prior, s.tried)
                                        for _, s, rc, cc, w, length, prior in jobs])
        done: dict[str, list[tuple[int, WindowFit | Fit]]] = {}
        for (generation, s, *_), fit in zip(jobs, fitted):
            done.setdefault(s.topic, []).append((generation, fit))
        asked: list[_Agreeing] = []
        with self._lock:
            for s in self._streams.values():
                if s is ref:
                    continue
                for generation, fit in done.get(s.topic, []):
                    if generation == s.generation:  # else the stream jumped while its window was fitted
                        self._record(s, fit)
                if self.params.method == 'refined' and s.topic in done and not s.silent:
                    a = self._to_agree(s)
                    if a is not None:
                        asked.append(a)
            params = self.params
        found = self.runner.run(_agreement, [(a.stream.topic, a.fits, a.newest, params.refined) for a in asked])
        with self._lock:
            for a, (est, restarted) in zip(asked, found):
                s = a.stream
                if s.generation == a.generation and s.correction is a.correction:  # else it changed meanwhile
                    self._settle(a, est, restarted)
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
            s.silent = quiet > self.params.silence_ns
            if s.silent and s.state is State.LOCKED:
                s.state = State.LOST
                s.message = f'silent for {quiet / 1e9:.1f} s; keeping the last correction'

    def prior(self, topic: str) -> int | None:
        """The offset of ``topic`` from arrival times (reference: 0)."""
        ref, s = self._streams[self.reference], self._streams[topic]
        if ref.median_lag is None or s.median_lag is None:
            return None
        g = self.params.grid_ns
        return int(round((s.median_lag - ref.median_lag) / g)) * g

    def _ready(self, ref: _Stream, s: _Stream) -> list[_Job]:
        """The windows of ``s`` whose data are complete and that have not been fitted."""
        p = self.params
        ref_last, cam_last = ref.bins.last_ns, s.bins.last_ns
        ref_origin = ref.bins.origin_ns
        if ref_last is None or cam_last is None or ref_origin is None or ref.since_ns is None or s.since_ns is None:
            return []
        prior = self._centre(s)
        if prior is None:
            return []
        g = p.grid_ns
        if p.method == 'paper':
            since = max(ref.since_ns, s.since_ns + prior)
            return self._ready_paper(ref, s, prior, since + -(since - ref_origin) % g)
        # the windows' grid starts at the reference's first event (after its last silence), whatever
        # the camera's prior: windows that shifted with it would share their data, and agree by it
        since = ref.since_ns + -(ref.since_ns - ref_origin) % g
        reach = p.reach_ns
        # the length from the span both streams have had since they (re)started: it keeps growing, and
        # starts short again after a clock jump, so that a jumped camera re-locks as fast as at the start
        length = p.refined.window_length(ref_last - max(since, s.since_ns + prior), tile=False)
        if length % g:
            return []
        newest = min(ref_last, cam_last + prior - reach)
        first = max(since, s.since_ns + prior, newest - p.drift_span_ns - length, s.restart_ns or since)
        first = since + -(-(first - since) // length) * length  # on the windows' grid
        jobs: list[_Job] = []
        for w in plan(first, newest, length):
            if (w, length) in s.fits:
                continue
            ref_counts = ref.bins.snapshot(w, w + length)
            cam_counts = s.bins.snapshot(w - prior - reach - 2 * g, w - prior + length + reach + 2 * g)
            jobs.append((s.generation, s, ref_counts, cam_counts, w, length, prior))
        return jobs

    def _ready_paper(self, ref: _Stream, s: _Stream, prior: int, since: int) -> list[_Job]:
        p = self.params
        T = p.window_ns
        ref_last, cam_last = ref.bins.last_ns, s.bins.last_ns
        assert ref_last is not None and cam_last is not None
        w = min(ref_last, cam_last + prior) - T
        w -= (w - since) % p.grid_ns
        if w < since or (s.last_start is not None and w < s.last_start + p.hop_ns):
            return []
        s.last_start = w
        return [(s.generation, s, ref.bins.snapshot(w, w + T), s.bins.snapshot(w - prior, w - prior + T), w, T,
                 prior)]

    def _centre(self, s: _Stream) -> int | None:
        """Where a new window of ``s`` is searched: the accepted line (at its anchor), else the
        arrival prior, on the grid."""
        g = self.params.grid_ns
        c = s.correction
        if c is not None and self.params.method == 'refined' and s.state is not State.SEEDED:
            return int(round(c.offset_ns / g)) * g
        return self.prior(s.topic)  # a seed is checked, not trusted: the search is the unseeded one

    def _record(self, s: _Stream, fit: WindowFit | Fit) -> None:
        s.tried += 1
        if isinstance(fit, WindowFit):
            s.fits[(fit.ref_start_ns, fit.length_ns)] = fit
            return
        self._record_paper(s, fit)

    def _to_agree(self, s: _Stream) -> _Agreeing | None:
        """What the camera's estimate is found from (None: no window): its windows of the drift
        span, by the agreement rule; and when it is locked and its newest windows all leave the
        line in force, those windows, for a line of their own (a clock step restarts it)."""
        p = self.params
        if not s.fits:
            return None
        restart = s.restart_ns if s.restart_ns is not None else -(1 << 62)
        since = [k for k in s.fits if k[0] >= restart]
        # one grid, since a step: the longest windows (the grid only grows; the shorter windows' keys
        # can start later than the longer ones', so the newest key does not tell the grid)
        length = max((k[1] for k in since), default=0)
        s.fits = {k: s.fits[k] for k in since if k[1] == length}
        if not s.fits:
            return None
        newest = max(k[0] for k in s.fits)
        span = sorted((k, f) for k, f in s.fits.items() if k[0] >= newest - p.drift_span_ns)
        s.fits = dict(span)
        fits = [f for _, f in span]
        stepped = None
        if s.correction is not None and s.state in (State.LOCKED, State.LOST):
            stepped = self._departing(s.correction, fits)
        return _Agreeing(s, s.generation, s.correction, fits, stepped)

    def _settle(self, a: _Agreeing, est: CameraFit, restarted: CameraFit | None) -> None:
        """The camera's state from its estimate ``est`` (or ``restarted``, an accepted line of its
        newest windows that left the line in force: the clock stepped)."""
        s, fits = a.stream, a.fits
        if restarted is not None and restarted.accepted and a.newest:
            c = s.correction
            assert c is not None
            s.restart_ns = min(f.ref_start_ns for f in a.newest)
            s.fits = {k: f for k, f in s.fits.items() if k[0] >= s.restart_ns}  # the line starts again from the step
            step_ns = restarted.offset_ns - (c.apply_one(restarted.anchor_ns) - restarted.anchor_ns)
            s.note = f'clock stepped by {step_ns / 1e6:+.3f} ms'
            est = restarted
        s.estimate = est
        note = f'{s.note}; ' if s.note else ''
        if est.accepted and s.state is State.SEEDED:
            s.note = self._seed_verdict(s, est.correction, est.anchor_ns, est.uncertainty_ns or 0.0)
        if est.accepted:
            s.correction = est.correction
            s.locked_on = est
            s.state = State.LOCKED
            s.message = f'locked; {s.note}' if s.note else 'locked'
            s.note = ''
        elif s.state is State.SEEDED:
            s.message = f'seeded from saved offsets; estimating: {est.reason}'
        elif s.correction is not None and s.state is State.LOCKED and not self._contradicts(s.correction, fits):
            # too few windows since the grid grew longer, or one astray among few: nothing speaks against
            # the lock (most windows with a clear peak still agree with it)
            s.message = f'locked; newest windows: {est.reason}'
        elif s.correction is not None:
            s.state = State.LOST
            s.message = f'{note}not accepted now, keeping the last correction: {est.reason}'
        else:
            s.state = State.ESTIMATING
            s.message = f'{note}estimating: {est.reason}'

    def _seed_verdict(self, s: _Stream, found: ClockCorrection, at_ns: int, se_ns: float) -> str:
        """What the stream's first own estimate says of its seed: '' when they agree (within 3
        standard errors plus the agreement's margin, or 1 ms), else a note that it was replaced."""
        assert s.correction is not None
        apart = found.apply_one(at_ns) - s.correction.apply_one(at_ns)
        if abs(apart) <= max(3 * se_ns + self.params.refined.systematic_ns, 1_000_000):
            return ''
        s.seeds_replaced += 1
        return f'the saved offset was {apart / 1e6:+.3f} ms off and is replaced'

    def _contradicts(self, c: ClockCorrection, fits: list[WindowFit]) -> bool:
        """Whether most windows with a clear peak put the camera away from correction ``c`` (more than
        3 standard errors plus the agreement's margin)."""
        clear = [f for f in fits if f.has_data and math.isfinite(f.se_ns)]
        away = [abs(f.offset_ns - (c.apply_one(_centre_of(f)) - _centre_of(f)))
                > 3 * f.se_ns + self.params.refined.systematic_ns for f in clear]
        return 2 * sum(away) > len(clear)

    def _departing(self, c: ClockCorrection, fits: list[WindowFit]) -> list[WindowFit] | None:
        """The newest ``min_agreeing`` windows when every one of them has a clear peak away from
        correction ``c`` (more than ``step_ns`` and 5 of its standard errors): a clock step, if they
        agree on a line of their own. None otherwise."""
        p = self.params
        newest = [f for f in fits[-p.refined.min_agreeing:] if f.has_data and math.isfinite(f.se_ns)]
        if len(newest) < p.refined.min_agreeing:
            return None
        departs = [abs(f.offset_ns - (c.apply_one(_centre_of(f)) - _centre_of(f))) > max(p.step_ns, 5 * f.se_ns)
                   for f in newest]
        return newest if all(departs) else None

    def _record_paper(self, s: _Stream, fit: Fit) -> None:
        p = self.params
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
        if s.paper_fits and abs(fit.offset_ns - s.paper_fits[-1].offset_ns) > p.step_ns:
            s.paper_fits.clear()  # the paper restamps by its newest accepted window
        s.paper_fits.append(fit)
        found = ClockCorrection(offset_ns=fit.offset_ns)
        verdict = self._seed_verdict(s, found, fit.ref_start_ns - fit.offset_ns, 0.0) if s.state is State.SEEDED else ''
        s.correction = found
        s.state = State.LOCKED
        s.message = f'locked; {verdict}' if verdict else 'locked'

    # -- reading (any thread) -------------------------------------------------------------------

    def correction(self, topic: str) -> ClockCorrection | None:
        """The correction a camera's messages get now, its known latency taken out (None: not locked
        since the last jump)."""
        return self._published(self._streams[topic])

    def _published(self, s: _Stream) -> ClockCorrection | None:
        c, delta = s.correction, self.latency_delta_ns[s.topic]
        return replace(c, offset_ns=c.offset_ns + delta) if c is not None and delta else c

    def state(self, topic: str) -> State:
        """The stream's state now."""
        return self._streams[topic].state

    def status(self, topic: str, now_ns: int | None = None) -> Status:
        """What a front end reports of ``topic`` (``now_ns`` on the arrival clock, for its silence)."""
        with self._lock:
            s = self._streams[topic]
            est = s.estimate
            held = s.locked_on if s.correction is not None else None
            last = s.last_fit
            if est is not None:
                cost, confidence = est.cost, est.confidence
                accepted = est.windows_agreeing if est.accepted else 0
                window = est.window_ns if est.accepted else None
            else:
                cost = last.cost if last else math.nan
                confidence = last.confidence if last else math.nan
                accepted = s.accepted
                good = s.paper_fits[-1] if s.paper_fits else None
                window = (good.ref_start_ns, good.ref_start_ns + self.params.window_ns) if good else None
            return Status(
                topic=topic, state=s.state, correction=self._published(s),
                prior_ns=0 if topic == self.reference else self.prior(topic),
                cost=cost, confidence=confidence, windows_tried=s.tried, windows_accepted=accepted, jumps=s.jumps,
                events=s.events, far_events=s.far_events + s.bins.far_events,
                silent_ns=None if s.last_receipt is None or now_ns is None else now_ns - s.last_receipt,
                window_ns=window, message=s.message, bins_bytes=s.bins.nbytes,
                uncertainty_ns=held.uncertainty_ns if held is not None else None,
                skew_uncertainty_ppm=held.skew_uncertainty_ppm if held is not None else None,
                reason=est.reason if est is not None else '', late_messages=s.late,
                seeds_replaced=s.seeds_replaced, frozen=self.frozen)

    @property
    def nbytes(self) -> int:
        """Bytes of bins held now, every stream together."""
        return sum(s.bins.nbytes for s in self._streams.values())

    def bins_ceiling_bytes(self, step_period_ns: int) -> int:
        """The most every stream's bins can hold together when ``step`` runs every ``step_period_ns``:
        each keeps ``_keep_ns`` behind its newest event, grows by a period between two steps, reaches
        at most ``jump_ns`` past its lag (later times are counted as far), and holds whole blocks."""
        span = self._keep_ns + step_period_ns + self.params.jump_ns
        return len(self._streams) * BinnedStream.ceiling_bytes(span, self.params.grid_ns)


def _centre_of(fit: WindowFit) -> int:
    """A window's centre on the camera's timeline."""
    return fit.ref_start_ns + fit.length_ns // 2 - fit.offset_ns
