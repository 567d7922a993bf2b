"""The engine: every camera's offset estimated while its events arrive, by one rule for every front
end. numpy only. A feeder calls ``add`` per message in the order they come (with its arrival time on
whatever clock it has), ``step`` from a timer (live) or as it reads (offline), and ``finish`` at the
end of a recording. How it works: docs/method.md, "One engine".
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterable, Mapping
from dataclasses import replace

import numpy as np

from evsync_ros.core.bins import BinnedStream
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.counts import MessageBins
from evsync_ros.core.density import TimeArray
from evsync_ros.core.engine.arrival import ArrivalTrack, prior_ns
from evsync_ros.core.engine.evidence import arrival_doubt, choose, settled
from evsync_ros.core.engine.jumps import jumped, model_systematic, unmatched
from evsync_ros.core.engine.lock import CameraLock, State
from evsync_ros.core.engine.params import LATENCY_LIMIT_NS, OnlineParams
from evsync_ros.core.engine.plan import job, window_jobs
from evsync_ros.core.engine.state import Alt, CameraStream, Job, Status
from evsync_ros.core.engine.windows import (
    Known,
    clearer,
    departing,
    fit_one,
    newest_line,
    on_stretch,
    stretch_of,
    with_whole,
)
from evsync_ros.core.errors import ParameterError, StreamError
from evsync_ros.core.host import HostEnvelope, clock_jumps
from evsync_ros.core.paper import PaperEstimate, WindowResult
from evsync_ros.core.results import CameraFit, Method, Prior, PriorChoice, WindowFit, latency_deltas
from evsync_ros.core.runner import InThread, Runner

__all__ = ['Engine', 'Status']


class Engine:
    """Every camera against ``reference``, estimated while events arrive (module notes).

    Args:
        topics: the streams, the reference among them.
        reference: the stream whose timeline the others join.
        params: the tracking and estimator parameters.
        latencies_ns: known envelope latencies per topic (``results.latency_deltas``), taken out of
            what the front end reads.
        runner: where ``step`` fits the windows and finds the agreement (``core.runner``); the
            calling thread when None. The caller closes it.
        offline: a recording read whole: every window is kept for the decision (live: the windows of
            ``drift_span_ns``), and ``finish`` ends it.
        priors_ns, corrections: per camera, where its windows are searched and a skew its times are
            binned through (an offline second pass); arrival times decide otherwise.

    Raises:
        StreamError: the reference is not among the topics, or there is no other.
        ParameterError: a latency is not whole nanoseconds within +-1 s.
    """

    def __init__(self, topics: Iterable[str], *, reference: str, params: OnlineParams = OnlineParams(),
                 latencies_ns: Mapping[str, int] | None = None, runner: Runner | None = None,
                 offline: bool = False, priors_ns: Mapping[str, int] | None = None,
                 corrections: Mapping[str, ClockCorrection] | None = None,
                 known: Mapping[str, Known] | None = None) -> None:
        topics = list(dict.fromkeys(topics))
        if reference not in topics:
            raise StreamError(f'reference stream {reference!r} is not among {sorted(topics)}')
        if len(topics) < 2 and not offline:
            raise StreamError('synchronisation needs the reference and at least one other stream')
        self.latency_delta_ns = _checked_latencies(latencies_ns, topics=topics, reference=reference)
        """What each camera's correction gets added: its known latency minus the reference's."""
        if params.window_ns % params.grid_ns:
            raise ParameterError('the window must be a whole number of the grid')
        if params.prior is PriorChoice.EVENTS:  # the events alone place every camera: the full range
            params = params.shifted(params.events_shift_ns)
        self.params = params
        self.reference = reference
        self.offline = offline
        self.runner: Runner = runner if runner is not None else InThread()
        self._lock = threading.Lock()
        priors, corrections, knowns = dict(priors_ns or {}), dict(corrections or {}), dict(known or {})
        margin = params.refined.systematic_ns
        self._streams = {
            t: CameraStream(t, params.grid_ns, ArrivalTrack(jump_ns=params.jump_ns, reach_ns=params.window_ns),
                            CameraLock(margin), corrections.get(t), priors.get(t), knowns.get(t, Known()))
            for t in topics}
        self._latency_known = set(latencies_ns or ())
        ref = self._streams[reference]
        ref.lock.state, ref.lock.message = State.LOCKED, 'reference'
        ref.lock.correction = ClockCorrection(offset_ns=0)
        reach = max(params.reach_ns, params.shifted(params.events_shift_ns).reach_ns if not offline else 0)
        self._keep_ns = params.drift_span_ns + 2 * params.window_ns + 2 * reach
        """Bins kept behind each stream's newest event, whatever its windows (memory bound)."""
        self.frozen = False
        """``freeze``: every correction stays as it is; no window is fitted."""
        self.ended = False
        self._arrivals = HostEnvelope()
        """Offline: each stream's least arrival lag per segment, for clock jumps too small for the lag
        line (``host.clock_jumps``, at ``finish``)."""
        self._peak = 0
        """The most bytes of bins held before any was freed (``peak_nbytes``)."""

    @property
    def topics(self) -> list[str]:
        """Every stream, the reference among them."""
        return list(self._streams)

    # -- operating (any thread) -----------------------------------------------------------------

    def seed(self, fit: CameraFit) -> None:
        """Correct ``fit.topic`` with a saved estimate (its latency delta included, as ``correction``
        gives it) until its own estimate is accepted (then locked; replaced and counted in
        ``seeds_replaced`` when they disagree). StreamError for a topic that is not a camera of this rig."""
        if fit.topic not in self._streams or fit.topic == self.reference:
            raise StreamError(f'{fit.topic}: not a camera of this rig to seed (reference {self.reference}, '
                              f'topics {sorted(self._streams)})')
        with self._lock:
            self._streams[fit.topic].lock.seed(replace(fit, offset_ns=fit.offset_ns - self.latency_delta_ns[fit.topic]))

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
                c, fit = s.lock.correction, s.lock.locked_on
                if s.topic == self.reference or c is None:
                    continue
                if fit is None or fit.correction != c:  # the paper's lock: a correction, no CameraFit
                    fit = CameraFit(topic=s.topic, offset_ns=c.offset_ns, skew_ppm=c.skew_ppm, anchor_ns=c.anchor_ns,
                                    accepted=True, cost=math.nan, confidence=math.nan, window_ns=(0, 0))
                out[s.topic] = replace(fit, offset_ns=fit.offset_ns + self.latency_delta_ns[s.topic])
            return out

    def set_model(self, topic: str, model: str) -> None:
        """What tells ``topic``'s camera model apart (its message type, encoding and geometry): a camera
        of another model than the reference's, whose latency is not known, carries
        ``refined.MODEL_SYSTEMATIC_NS`` more error (they respond to one edge at different times)."""
        with self._lock:
            self._stream(topic).model = model
            ref_model = self._streams[self.reference].model
            for s in self._streams.values():
                if s.topic == self.reference or not s.model or not ref_model:
                    continue
                s.known = replace(s.known, systematic_ns=model_systematic(
                    s.model, ref_model, latency_known=s.topic in self._latency_known))

    # -- feeding (any thread) -------------------------------------------------------------------

    def add(self, topic: str, times: TimeArray, receipt_ns: int | None, *, lo: int | None = None,
            hi: int | None = None) -> bool:
        """Bin one message's event times (``receipt_ns``: when it arrived, on the one clock the
        feeder has for every stream; None: not known, as for arrays); False when the message showed
        a clock jump (the stream starts over: its messages go out uncorrected until it locks again).
        ``lo``, ``hi``: the least and greatest of ``times``, when the feeder has them (a batch's, found
        together). StreamError for a topic not tracked."""
        s = self._stream(topic)
        with self._lock:
            if not self._arrived(s, receipt_ns, times.size):
                return True
            if lo is None or hi is None:
                lo, hi = int(times.min()), int(times.max())
            jumped = False
            if receipt_ns is not None:
                jumped, floor, ceiling = self._lag(s, receipt_ns, int(times[-1]))
                if lo < floor or hi > ceiling:  # (two scalar tests: this runs for every message)
                    far = (times < floor) | (times > ceiling)
                    s.far_events += int(far.sum())
                    times = times[~far]
                    if times.size:
                        lo, hi = int(times.min()), int(times.max())
            if times.size:
                self._start(s, lo)
                s.bins.add(times, lo=lo, hi=hi)
                s.events += int(times.size)
                if self.offline and receipt_ns is not None:
                    self._arrivals.add(topic, hi, receipt_ns)
            return not jumped

    def add_bins(self, topic: str, m: MessageBins) -> bool:
        """``add`` for a message already counted on this engine's grid (``MessageBins.of`` with
        ``params.grid_ns``: what a camera process sends). Far events are judged by their bin."""
        s = self._stream(topic)
        with self._lock:
            if not self._arrived(s, m.receipt_ns, m.events):
                return True
            jumped, floor, ceiling = self._lag(s, m.receipt_ns, m.hi_ns)
            bins, counts, lo, hi = m.bins, m.counts, m.lo_ns, m.hi_ns
            if lo < floor or hi > ceiling:
                g = self.params.grid_ns
                starts = bins * g
                near = (starts + g > floor) & (starts <= ceiling)
                s.far_events += int(counts[~near].sum())
                bins, counts = bins[near], counts[near]
                if bins.size:
                    lo, hi = max(lo, int(bins[0]) * g), min(hi, int(bins[-1] + 1) * g - 1)
            if bins.size:
                self._start(s, lo)
                s.bins.add_bins(bins, counts, lo=lo, hi=hi, mid=min(max(m.mid_ns, lo), hi))
                s.events += int(counts.sum())
            return not jumped

    def _stream(self, topic: str) -> CameraStream:
        s = self._streams.get(topic)
        if s is None:
            raise StreamError(f'{topic!r} is not a stream of this synchronisation')
        return s

    def _arrived(self, s: CameraStream, receipt_ns: int | None, events: int) -> bool:
        """A message arrived (silence ends); False when it has no events."""
        if receipt_ns is not None:
            s.resumed = s.last_receipt is not None and receipt_ns - s.last_receipt > self.params.silence_ns
            s.last_receipt = receipt_ns
            s.arrivals += 1
        s.silent = False
        if s.lock.state is State.LOST and s.paper.done:  # lost only by silence: its loop has ended
            s.lock.state, s.lock.message = State.LOCKED, 'locked; back from a silence'
        return events > 0

    def _lag(self, s: CameraStream, receipt_ns: int, mid_ns: int) -> tuple[bool, int, int]:
        """Judge a message's arrival lag (``arrival.ArrivalTrack``): whether the clock jumped, and the
        least and greatest event time that are not far."""
        verdict = s.arrival.add(receipt_ns, mid_ns)
        s.late += verdict.late
        if verdict.jumped_ns is not None:
            s.jumps_seen.append((receipt_ns, mid_ns - (s.first_ns or mid_ns), -verdict.jumped_ns))
            self._jump(s, verdict.jumped_ns)
        if s.topic == self.reference:
            if s.lock.state is not State.LOCKED:  # back from a silence: the reference is its own timeline
                s.lock.state, s.lock.message = State.LOCKED, 'reference'
        elif s.lock.state is State.WAITING:
            s.lock.state, s.lock.message = State.ESTIMATING, 'estimating: waiting for whole windows'
        return verdict.jumped_ns is not None, verdict.floor_ns, verdict.ceiling_ns

    def _start(self, s: CameraStream, lo: int) -> None:
        """The stream's windows begin after a silence (or at its first event); one grid for all."""
        if s.resumed or s.since_ns is None:
            s.since_ns = lo
        if s.first_ns is None:
            s.first_ns = lo
        if s.bins.origin_ns is None:
            s.bins.origin_ns = lo - lo % self.params.grid_ns
        if s.topic != self.reference and s.lock.state is State.WAITING:
            s.lock.state, s.lock.message = State.ESTIMATING, 'estimating: waiting for whole windows'

    def _jump(self, s: CameraStream, by_ns: int) -> None:
        s.jumps += 1
        self._peak = self.peak_nbytes  # the stream's bins are about to go
        what = f'clock jump of {-by_ns / 1e9:+.3f} s in arrival lag'
        if s.topic == self.reference:
            s.reset(State.LOCKED, f'{what}; every camera re-acquires')
            s.lock.correction = ClockCorrection(offset_ns=0)
            for other in self._streams.values():
                if other is not s:
                    other.forget(State.WAITING if other.lock.state is State.WAITING else State.ESTIMATING,
                                 f'the reference ({self.reference}) jumped; re-acquiring')
        else:
            s.reset(State.ESTIMATING, f'{what}; re-acquiring')
        s.lock.note = what

    # -- estimating (timer thread) --------------------------------------------------------------

    def step(self, now_ns: int | None = None, *, decide: bool = True) -> int:
        """Fit every window that is ready and (``decide``) update each camera's decision; returns how
        many windows were fitted. ``now_ns``: the feeder's clock, for silence (None: no silence).
        Counts are copied under the lock, and the windows fitted and their agreement found outside
        it, by the runner, so that ``add`` (another thread) waits only for the copies."""
        jobs: list[Job] = []
        with self._lock:
            if now_ns is not None:
                self._silence(now_ns)
            if self.frozen:  # the corrections in force stay; the bins go on (memory), nothing is fitted
                self._trim()
                return 0
            params = self.params
            ref = self._streams[self.reference]
            for s in self._streams.values():
                if s is not ref:
                    jobs += self._ready(ref, s)
            self._trim()  # after the windows ready took their copies
        events = params.shifted(params.events_shift_ns)
        fitted = self.runner.run(fit_one, [(events if alt else params, rc, cc, w, length, prior, self._index(s, w),
                                            self.offline) for _, s, alt, rc, cc, w, length, prior in jobs])
        done: set[str] = set()
        with self._lock:
            for (generation, s, alt, *_), fit in zip(jobs, fitted):
                if generation == s.generation:  # else the stream jumped while its window was fitted
                    self._record(s, fit, alt)
                    done.add(s.topic)
        if decide:
            self._decide([s for s in self._streams.values() if s.topic in done and not s.silent])
        return len(jobs)

    def _decide(self, streams: list[CameraStream]) -> None:
        """Each refined camera's decision from its windows (``refined.camera_result``), and its lock."""
        if self.params.method is not Method.REFINED:
            return
        with self._lock:
            asked = [(s, s.generation, s.lock.correction, *self._to_agree(s), self._alt_fits(s)) for s in streams]
            asked = [a for a in asked if a[3] or a[5]]
            params = self.params.refined
            events = self.params.shifted(self.params.events_shift_ns).refined
        found = self.runner.run(newest_line, [(s.topic, fits, newest, params, s.known)
                                              for s, _, _, fits, newest, _ in asked]
                                + [(s.topic, alt, None, events, s.known) for s, *_, alt in asked if alt])
        own = [(self._stretched(s, est), restarted) for (s, *_), (est, restarted) in zip(asked, found)]
        alts = iter(found[len(asked):])
        with self._lock:
            for (s, generation, correction, _, newest, alt), (est, restarted) in zip(asked, own):
                alt_est = next(alts)[0] if alt else None
                if self.offline:  # a recording read whole is decided once, at its end: no lock to keep
                    s.estimate = replace(est, windows=with_whole(est.windows, s.whole))
                elif s.generation == generation and s.lock.correction is correction:  # else it changed meanwhile
                    self._settle(s, est, restarted, newest, alt_est)

    def _trim(self) -> None:
        self._peak = self.peak_nbytes  # before any is freed
        keep = self._keep_ns
        ref = self._streams[self.reference].bins
        p = self.params
        if self.offline and ref.first_ns is not None and ref.last_ns is not None and (
                ref.last_ns - ref.first_ns >= p.refined.windows_wanted * p.window_ns):
            # offline, once the windows are as long as they get, no window is fitted again: the bins
            # of the windows not yet fitted are all that is needed (memory follows the window)
            keep = 2 * p.window_ns + 2 * p.reach_ns
        floors = self._paper_floors() if self.offline and p.method is Method.PAPER else {}
        for s in self._streams.values():
            if s.bins.last_ns is not None:
                s.bins.drop_before(min(s.bins.last_ns - keep, floors.get(s.topic, s.bins.last_ns)))

    def _silence(self, now_ns: int) -> None:
        for s in self._streams.values():
            if s.last_receipt is None:
                continue
            quiet = now_ns - s.last_receipt
            s.silent = quiet > self.params.silence_ns
            if s.silent and s.lock.state is State.LOCKED:
                s.lock.state = State.LOST
                s.lock.message = f'silent for {quiet / 1e9:.1f} s; keeping the last correction'

    def prior(self, topic: str) -> int | None:
        """The offset of ``topic`` where its windows are searched: given by the feeder, else where
        ``placed`` says (reference: 0)."""
        ref, s = self._streams[self.reference], self._streams[topic]
        if s is ref:
            return 0
        g = self.params.grid_ns
        if s.fixed_prior_ns is not None:
            return int(round(s.fixed_prior_ns / g)) * g
        return self.events_prior(topic) if self.placed(topic) is Prior.EVENTS else self.arrival_prior(topic)

    def placed(self, topic: str) -> Prior:
        """What places the windows of ``topic`` (``prior``): its arrival times where the feeder has them
        and the events alone are not asked for (``OnlineParams.prior``), else its events."""
        s = self._streams[topic]
        return Prior.EVENTS if self.params.prior is PriorChoice.EVENTS or s.last_receipt is None else Prior.ARRIVAL

    def arrival_prior(self, topic: str) -> int | None:
        """The offset of ``topic`` its arrival times give (``arrival.prior_ns``; None: not known)."""
        ref, s = self._streams[self.reference], self._streams[topic]
        return 0 if s is ref else prior_ns(s.arrival, ref.arrival, grid_ns=self.params.grid_ns)

    def events_prior(self, topic: str) -> int | None:
        """The offset of ``topic`` its first events give against the reference's (the cameras began about
        together), on the grid (None: one has no event yet)."""
        ref, s = self._streams[self.reference], self._streams[topic]
        if ref.first_ns is None or s.first_ns is None:
            return None
        g = self.params.grid_ns
        return int(round((ref.first_ns - s.first_ns) / g)) * g

    def doubt(self, topic: str) -> str:
        """Why the arrival times of ``topic`` or the reference are not one clock's arrivals before any
        window says so ('' when nothing does; ``evidence.arrival_doubt``)."""
        ref, s = self._streams[self.reference], self._streams[topic]
        return (arrival_doubt(s.arrivals, s.late)
                or arrival_doubt(ref.arrivals, ref.late).replace('its', "the reference's", 1))

    def _ready(self, ref: CameraStream, s: CameraStream) -> list[Job]:
        """The windows of ``s`` whose data are complete and that have not been fitted."""
        prior = self._centre(s)
        if prior is None:
            return []
        if self.params.method is Method.PAPER:
            return self._paper_ready(ref, s, prior)
        jobs = window_jobs(self.params, ref.bins, s.bins, ref_since=ref.since_ns, cam_since=s.since_ns, prior=prior,
                           restart=s.restart_ns, resumed=s.since_ns != s.first_ns, fitted=s.fits,
                           ended=self.ended, whole=self.offline)
        out: list[Job] = [(s.generation, s, False, *job) for job in jobs]
        alt = self._alt(s)
        if alt is not None:
            jobs = window_jobs(self.params.shifted(self.params.events_shift_ns), ref.bins, s.bins,
                               ref_since=ref.since_ns, cam_since=s.since_ns, prior=alt.centre_ns,
                               restart=s.restart_ns, resumed=s.since_ns != s.first_ns, fitted=alt.fits,
                               ended=self.ended, whole=self.offline)
            out += [(s.generation, s, True, *job) for job in jobs]
        return out

    def _alt(self, s: CameraStream) -> Alt | None:
        """Live: the camera's windows placed by its events alone and searched over the full range
        (``evidence``), while its own decision under the arrival prior does not stand; None when they are
        not needed. Once they agree on a line, they follow it."""
        arrival, events = self.arrival_prior(s.topic), self.events_prior(s.topic)
        if (self.offline or self.params.method is not Method.REFINED or self.params.prior is not PriorChoice.AUTO
                or s.fixed_prior_ns is not None or s.last_receipt is None or arrival is None or events is None
                or settled(s.own, arrival, s.bins.last_ns or 0)):
            s.alt = None
            return None
        if s.alt is None:
            s.alt = Alt(centre_ns=events)
        found = s.alt.estimate
        if found is not None and found.accepted:
            g = self.params.grid_ns
            s.alt.centre_ns = int(round(found.offset_ns / g)) * g
        return s.alt

    def _alt_fits(self, s: CameraStream) -> list[WindowFit] | None:
        """The windows of the camera's events-placed decision (``Alt``), as ``_to_agree`` keeps its own."""
        if s.alt is None:
            return None
        s.alt.fits = self._kept(s, s.alt.fits)
        return list(s.alt.fits.values()) or None

    def _paper_ready(self, ref: CameraStream, s: CameraStream, prior: int) -> list[Job]:
        """The paper's loop (``paperloop.PaperLoop``): its next windows, until one is accepted."""
        s.paper.begin(ref.bins, s.bins, ref_since=ref.since_ns, cam_since=s.since_ns, prior=prior)
        return [(s.generation, s, False, *job) for job in s.paper.next_jobs(self.params, ref.bins, s.bins)]

    def _paper_floors(self) -> dict[str, int]:
        """Offline: per stream, where the bins its loops have still to try begin (``PaperLoop.floor``)."""
        floors: dict[str, int] = {}
        for s in self._streams.values():
            floor = s.paper.floor(self.params.window_ns) if s.topic != self.reference else None
            if floor is not None:
                floors[self.reference] = min(floors.get(self.reference, floor[0]), floor[0])
                floors[s.topic] = floor[1]
        return floors

    def _index(self, s: CameraStream, w: int) -> int:
        """A window's number in the paper's loop (0 for the refined method, which does not number them)."""
        return s.paper.index(w, self.params.window_ns)

    def _centre(self, s: CameraStream) -> int | None:
        """Where a new window of ``s`` is searched: the accepted line (at its anchor), else the prior."""
        g = self.params.grid_ns
        c = s.lock.correction
        if c is not None and self.params.method is Method.REFINED and s.lock.state is not State.SEEDED:
            return int(round(c.offset_ns / g)) * g
        return self.prior(s.topic)  # a seed is checked, not trusted: the search is the unseeded one

    def _record(self, s: CameraStream, fit: WindowFit | WindowResult, alt: bool = False) -> None:
        if isinstance(fit, WindowResult):
            self._record_paper(s, fit)
            return
        if alt:
            if s.alt is not None:
                s.alt.fits[(fit.ref_start_ns, fit.length_ns)] = fit.light()
            return
        s.tried += 1
        if fit.ncc.size and clearer(fit, s.whole):
            s.whole = fit
        s.fits[(fit.ref_start_ns, fit.length_ns)] = fit.light()

    def _to_agree(self, s: CameraStream) -> tuple[list[WindowFit], list[WindowFit] | None]:
        """What the camera's decision is found from: its windows (live: of the drift span) of the
        longest length since a step; and when it is locked and its newest windows all leave the line
        in force, those windows, for a line of their own (a clock step restarts it)."""
        s.fits = self._kept(s, s.fits)
        if not s.fits:
            return [], None
        fits = list(s.fits.values())
        stepped = None
        if s.lock.correction is not None and s.lock.state in (State.LOCKED, State.LOST):
            stepped = departing(s.lock.correction, fits, self.params)
        return fits, stepped

    def _kept(self, s: CameraStream, fits: dict[tuple[int, int], WindowFit]) -> dict[tuple[int, int], WindowFit]:
        """The windows of ``fits`` a decision is found from: those since the camera's last step or
        silence, of the longest length (live: of the drift span), in order."""
        restart = s.restart_ns if s.restart_ns is not None else -(1 << 62)
        prior = self._centre(s)
        if s.since_ns != s.first_ns and s.since_ns is not None and prior is not None:
            # back from a silence: its windows start short again, and only they make the decision
            restart = max(restart, s.since_ns + prior)
        since = [k for k in fits if k[0] >= restart]
        length = max((k[1] for k in since), default=0)  # the grid only grows: the longest windows
        kept = {k: fits[k] for k in since if k[1] == length}
        if not kept:
            return {}
        newest = max(k[0] for k in kept)
        keep = -(1 << 62) if self.offline else newest - self.params.drift_span_ns
        return dict(sorted((k, f) for k, f in kept.items() if k[0] >= keep))

    def _settle(self, s: CameraStream, est: CameraFit, restarted: CameraFit | None,
                newest: list[WindowFit] | None, alt: CameraFit | None) -> None:
        """The camera's decision ``est`` (or ``restarted``, an accepted line of its newest windows that
        left the line in force: the clock stepped), or its events-placed decision ``alt`` where
        ``evidence.choose`` takes that, into its lock."""
        c = s.lock.correction
        if restarted is not None and restarted.accepted and newest and c is not None:
            s.restart_ns = min(f.ref_start_ns for f in newest)
            s.fits = {k: f for k, f in s.fits.items() if k[0] >= s.restart_ns}  # the line starts again from the step
            step_ns = restarted.offset_ns - (c.apply_one(restarted.anchor_ns) - restarted.anchor_ns)
            s.lock.note = f'clock stepped by {step_ns / 1e6:+.3f} ms'
            s.lock.state = State.ESTIMATING  # a step is a new line, not a move of the old one
            est = restarted
        s.own = est
        if s.alt is not None and alt is not None:
            s.alt.estimate = alt
        s.estimate = self.said(s.topic, est, alt)
        s.lock.decide(s.estimate)

    def said(self, topic: str, own: CameraFit, alt: CameraFit | None = None) -> CameraFit:
        """A camera's decision with what placed it said (``evidence.choose`` between ``own``, its windows
        placed as ``prior`` places them, and ``alt``, its events-placed windows' decision where tried)."""
        s = self._streams[topic]
        if s.fixed_prior_ns is not None:  # placed by the driver, which says by what
            return own
        kind = self.placed(topic)
        if kind is Prior.EVENTS or self.params.method is Method.PAPER:
            why = '' if kind is Prior.ARRIVAL else (
                'no arrival times' if s.last_receipt is None else 'the events alone were asked for')
            return replace(own, prior=kind, prior_reason=why)
        return choose(own, alt, arrival_ns=self.arrival_prior(topic), at_ns=s.bins.last_ns or 0,
                      doubt=self.doubt(topic))

    def _record_paper(self, s: CameraStream, fit: WindowResult) -> None:
        """One window of the paper's loop, in order: the camera's decision is the loop's outcome so far
        (``PaperEstimate.of``), and the loop ends at its first accepted window."""
        outcome = s.paper.take(fit)
        if outcome is None:
            return
        s.tried += 1
        s.accepted += fit.accepted
        s.estimate = outcome.as_camera(s.topic, params=self.params.paper)
        if not self.offline:
            s.lock.decide(s.estimate)

    # -- the end of a recording (offline) --------------------------------------------------------

    def finish(self) -> dict[str, CameraFit]:
        """Every stream has ended: the windows their ends allow are fitted (what live cannot know),
        and each camera's decision is made over all of its windows. StreamError: a stream had no event."""
        empty = [t for t, s in self._streams.items() if s.bins.origin_ns is None]
        if empty:
            raise StreamError(f'no events to estimate from on {", ".join(sorted(empty))}')
        self.ended = True
        self.step(decide=False)
        cams = [s for s in self._streams.values() if s.topic != self.reference]
        for s in cams:
            if not s.fits and self.params.method is Method.REFINED:
                self._fit_from_start(s)
            elif not s.paper.windows and self.params.method is Method.PAPER:
                self._paper_from_start(s)
        self._decide(cams)
        out = {s.topic: self.said(s.topic, self._where(s, s.estimate if s.estimate is not None else self._undecided(s)))
               for s in cams}
        spans = {t: span for t in self._streams if (span := self.first_last(t)) is not None}
        for topic, (at_ns, by_ns) in clock_jumps(self._arrivals.within(spans), self.reference).items():
            out[topic] = jumped(out[topic], at_ns=at_ns, by_ns=by_ns, first_ns=spans[topic][0])
        ref = self._streams[self.reference]
        for s in cams:  # a jump of its clock against the reference's: no one line holds the recording
            own = unmatched(s.jumps_seen, ref.jumps_seen, self.params.jump_ns)
            theirs = unmatched(ref.jumps_seen, s.jumps_seen, self.params.jump_ns)
            if own or theirs:
                _, at, by = own[0] if own else (0, theirs[0][1], -theirs[0][2])
                out[s.topic] = jumped(out[s.topic], at_ns=at, by_ns=by, first_ns=0)
        return out

    def _stretched(self, s: CameraStream, est: CameraFit) -> CameraFit:
        """``est``, or when it is refused only for quiet windows outside a stretch, decided again on
        that stretch's own windows (``on_stretch``); the stretch's decision is kept while the
        stretch and the stream's generation stay."""
        span = stretch_of(est)
        if span is None:
            return est
        key = (span, s.generation)
        if s.stretch is None or s.stretch[0] != key:
            with self._lock:
                jobs = self._stretch_jobs(s, span, est)
            if not jobs:
                return est
            fits = [f for f in self.runner.run(fit_one, jobs) if isinstance(f, WindowFit)]
            s.stretch = (key, newest_line(s.topic, fits, None, self.params.refined, s.known)[0])
        return on_stretch(est, s.stretch[1])

    def _stretch_jobs(self, s: CameraStream, span: tuple[int, int], est: CameraFit) -> list[tuple[object, ...]]:
        """The windows of ``span`` (reference timeline) planned as for a recording of its length (what
        ``evsync estimate --start --duration`` would do), while its bins are held; none when they
        would be no shorter than the decision's, too few or too many."""
        ref, p = self._streams[self.reference], self.params
        start, end = span
        prior = self._centre(s)
        length = p.refined.window_length(end - start, tile=False)
        starts = range(start, end - length + 1, length)
        if (prior is None or ref.bins.first_ns is None or ref.bins.first_ns > start or length % p.grid_ns
                or not p.refined.min_agreeing <= len(starts) <= 4 * p.refined.windows_wanted
                or length >= min(f.length_ns for f in est.windows)):  # only shorter windows add evidence
            return []
        return [(p, *job(p, ref.bins, s.bins, w, length, prior), s.tried, False) for w in starts]

    def _where(self, s: CameraStream, fit: CameraFit) -> CameraFit:
        """A camera not accepted, its reason saying where it was searched (its arrival-time prior
        against its first events' difference: a prior far from the first events' is worth knowing)."""
        ref = self._streams[self.reference]
        prior = self.prior(s.topic)
        if (fit.accepted or prior is None or s.fixed_prior_ns is not None or s.last_receipt is None
                or self.params.method is Method.PAPER):
            return fit
        if self.placed(s.topic) is Prior.EVENTS:
            where = f'searched within {self.params.refined.max_shift_ns / 1e9:g} s of where its first events put it'
            return replace(fit, reason=f'{fit.reason} ({where})')
        where = f'searched within {self.params.refined.max_shift_ns / 1e9:g} s of where its arrival times put it'
        if ref.first_ns is not None and s.first_ns is not None:
            where += f', {(prior - (ref.first_ns - s.first_ns)) / 1e9:+.3f} s from where its first events do'
        return replace(fit, reason=f'{fit.reason} ({where})')

    def _fit_from_start(self, s: CameraStream) -> None:
        """A recording shorter than one whole window: its one window from the reference's start."""
        ref = self._streams[self.reference]
        prior = self._centre(s)
        if prior is None or ref.since_ns is None:
            return
        p = self.params
        length = p.refined.window_length(0)
        w = ref.since_ns + -(ref.since_ns - (ref.bins.origin_ns or 0)) % p.grid_ns
        self._record(s, fit_one(p, *job(p, ref.bins, s.bins, w, length, prior), s.tried, self.offline))

    def _paper_from_start(self, s: CameraStream) -> None:
        """The paper's loop on a recording shorter than its window: its one partial window 0."""
        ref, prior = self._streams[self.reference], self._centre(s)
        if prior is not None:
            s.paper.begin(ref.bins, s.bins, ref_since=ref.since_ns, cam_since=s.since_ns, prior=prior)
        first = s.paper.first_job(self.params, ref.bins, s.bins)
        if first is not None:
            self._record(s, fit_one(self.params, *first, 0, True))

    def paper_estimate(self, topic: str) -> PaperEstimate | None:
        """The paper's loop's outcome for a camera (None: no window tried, or the refined method)."""
        return self._streams[topic].paper.outcome()

    @property
    def done(self) -> bool:
        """Nothing later in the recording can change a decision: the paper's loop has ended for every
        camera (a reader may stop). Never for the refined method, which uses every window."""
        return self.params.method is Method.PAPER and all(
            s.paper.done for s in self._streams.values() if s.topic != self.reference)

    def _undecided(self, s: CameraStream) -> CameraFit:
        return CameraFit(topic=s.topic, offset_ns=self.prior(s.topic) or 0, skew_ppm=0.0, anchor_ns=0,
                         accepted=False, cost=math.inf, confidence=0.0, window_ns=(0, 0),
                         reason='too short: no window with events of both cameras')

    # -- reading (any thread) -------------------------------------------------------------------

    def correction(self, topic: str) -> ClockCorrection | None:
        """The correction a camera's messages get now, its known latency taken out (None: not locked
        since the last jump)."""
        s = self._streams[topic]
        return s.lock.published(self.latency_delta_ns[topic])

    def state(self, topic: str) -> State:
        """The stream's state now."""
        return self._streams[topic].lock.state

    def status(self, topic: str, now_ns: int | None = None) -> Status:
        """What a front end reports of ``topic`` (``now_ns`` on the arrival clock, for its silence)."""
        with self._lock:
            s = self._streams[topic]
            lock, est = s.lock, s.estimate
            held = lock.locked_on if lock.correction is not None else None
            behind = held if lock.state is State.LOCKED and held is not None else est
            cost = est.cost if est is not None else math.nan
            confidence = est.confidence if est is not None else math.nan
            accepted = s.accepted if self.params.method is Method.PAPER else (
                est.windows_agreeing if est is not None and est.accepted else 0)
            window = held.window_ns if held is not None and held.accepted else None
            return Status(
                topic=topic, state=lock.state, correction=lock.published(self.latency_delta_ns[topic]),
                prior_ns=self.prior(topic), cost=cost, confidence=confidence, windows_tried=s.tried,
                windows_accepted=accepted, jumps=s.jumps, events=s.events,
                far_events=s.far_events + s.bins.far_events,
                silent_ns=None if s.last_receipt is None or now_ns is None else now_ns - s.last_receipt,
                window_ns=window, message=lock.message, bins_bytes=s.bins.nbytes,
                uncertainty_ns=held.uncertainty_ns if held is not None else None,
                skew_uncertainty_ppm=held.skew_uncertainty_ppm if held is not None else None,
                reason=behind.reason if behind is not None else '', late_messages=s.late,
                seeds_replaced=lock.seeds_replaced, frozen=self.frozen,
                prior=est.prior if est is not None else None, prior_reason=est.prior_reason if est is not None else '')

    @property
    def nbytes(self) -> int:
        """Bytes of bins held now, every stream together."""
        return sum(s.bins.nbytes for s in self._streams.values())

    @property
    def peak_nbytes(self) -> int:
        """The most bytes of bins held at once so far, every stream together: bins are freed only by
        a step or a clock jump, each of which notes what was held first, so no message needs to."""
        return max(self._peak, self.nbytes)

    @property
    def far_events(self) -> dict[str, int]:
        """Events far from their stream's lag or message (corrupt times: counted, not used), per stream."""
        out = {t: s.far_events + s.bins.far_events for t, s in self._streams.items()}
        return {t: n for t, n in out.items() if n}

    @property
    def late_events(self) -> dict[str, int]:
        """Events that came after their bins were freed (counted, not used), per stream."""
        out = {t: s.bins.dropped_late for t, s in self._streams.items()}
        return {t: n for t, n in out.items() if n}

    def known(self, topic: str) -> Known:
        """What ``topic``'s decision knows beyond its windows (its systematic error, a skew taken out)."""
        return self._streams[topic].known

    def first_last(self, topic: str) -> tuple[int, int] | None:
        """A stream's first and last binned event (None: none)."""
        b = self._streams[topic].bins
        return None if b.first_ns is None or b.last_ns is None else (b.first_ns, b.last_ns)

    def bins_ceiling_bytes(self, step_period_ns: int) -> int:
        """The most every stream's bins can hold together when ``step`` runs every ``step_period_ns``:
        each keeps ``_keep_ns`` behind its newest event, grows by a period between two steps, reaches
        at most ``jump_ns`` past its lag (later times are counted as far), and holds whole blocks."""
        span = self._keep_ns + step_period_ns + self.params.jump_ns
        return len(self._streams) * BinnedStream.ceiling_bytes(span, self.params.grid_ns)


def _checked_latencies(latencies_ns: Mapping[str, int] | None, *, topics: list[str], reference: str
                       ) -> dict[str, int]:
    latencies_ns = dict(latencies_ns or {})
    for topic, value in latencies_ns.items():
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or abs(value) > LATENCY_LIMIT_NS:
            raise ParameterError(f'latency of {topic} must be whole nanoseconds within +-1 s, got {value!r}')
    return latency_deltas(latencies_ns, topics=topics, reference=reference)
