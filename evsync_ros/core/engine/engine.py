"""The engine: every camera's offset estimated while its events arrive, by one rule for every front end
(docs/method.md, "One engine"). numpy only."""

from __future__ import annotations

import threading
from collections.abc import Iterable, Mapping
from dataclasses import replace

import numpy as np

from evsync_ros.core.bins import BinnedStream
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.counts import MessageBins
from evsync_ros.core.density import TimeArray
from evsync_ros.core.engine import feed, placement, report
from evsync_ros.core.engine.arrival import ArrivalTrack
from evsync_ros.core.engine.decide import since_step
from evsync_ros.core.engine.drivers import Driver, Live
from evsync_ros.core.engine.jumps import model_systematic
from evsync_ros.core.engine.lock import CameraLock, State
from evsync_ros.core.engine.methods import METHODS, WindowMethod
from evsync_ros.core.engine.methods.refined import Alt, Windows
from evsync_ros.core.engine.params import LATENCY_LIMIT_NS, EngineParams
from evsync_ros.core.engine.stream import CameraStream, Job, Known, Status
from evsync_ros.core.errors import ParameterError, StreamError
from evsync_ros.core.host import HostEnvelope
from evsync_ros.core.paper import PaperEstimate
from evsync_ros.core.results import CameraFit, Method, PriorChoice, WindowFit, latency_deltas
from evsync_ros.core.runner import InThread, Runner

__all__ = ['Engine', 'Status']


class Engine:
    """Every camera against ``reference``, estimated while events arrive: ``add`` each message,
    ``step`` to plan, fit, decide and apply (docs/method.md, "One engine").

    ``topics``: the streams, ``reference`` among them; ``latencies_ns``: known envelope latencies per
    topic, taken out of what the front end reads; ``runner``: where ``step`` fits and decides (the
    calling thread when None; the caller closes it); ``driver``: ``drivers.Live`` (the default) or
    ``drivers.Offline`` (a recording read whole, ``finish`` at its end); ``priors_ns``, ``corrections``,
    ``known``: per camera, where its windows are searched, a skew its times are binned through (the
    offline driver's later reads), what its decision knows beyond them. StreamError: the reference is
    not among the topics, or (live) there is no other; ParameterError: a latency beyond +-1 s.
    """

    def __init__(self, topics: Iterable[str], *, reference: str, params: EngineParams = EngineParams(),
                 latencies_ns: Mapping[str, int] | None = None, runner: Runner | None = None,
                 driver: Driver | None = None, priors_ns: Mapping[str, int] | None = None,
                 corrections: Mapping[str, ClockCorrection] | None = None,
                 known: Mapping[str, Known] | None = None) -> None:
        topics = list(dict.fromkeys(topics))
        self.driver: Driver = driver if driver is not None else Live()
        if reference not in topics:
            raise StreamError(f'reference stream {reference!r} is not among {sorted(topics)}')
        if len(topics) < 2 and isinstance(self.driver, Live):
            raise StreamError('synchronisation needs the reference and at least one other stream')
        self.latency_delta_ns = _checked_latencies(latencies_ns, topics=topics, reference=reference)
        """What each camera's correction gets added: its known latency minus the reference's."""
        if params.window_ns % params.grid_ns:
            raise ParameterError('the window must be a whole number of the grid')
        if params.prior is PriorChoice.EVENTS:  # the events alone place every camera: the full range
            params = params.shifted(params.events_shift_ns)
        self.params, self.reference = params, reference
        self.runner: Runner = runner if runner is not None else InThread()
        self.method: WindowMethod = METHODS[Method(params.method)]()
        self.lock = threading.Lock()
        self.envelope = HostEnvelope()
        """Each stream's least arrival lag per segment: the clock-step rule's finer evidence."""
        priors, known = dict(priors_ns or {}), dict(known or {})
        self._streams = {t: CameraStream(t, params.grid_ns, ArrivalTrack(jump_ns=params.jump_ns,
                                                                         reach_ns=params.window_ns),
                                         CameraLock(params.refined.systematic_ns), (corrections or {}).get(t),
                                         priors.get(t), known.get(t, Known())) for t in topics}
        self._latency_known = set(latencies_ns or ())
        ref = self._streams[reference]
        ref.lock.state, ref.lock.message, ref.lock.correction = State.LOCKED, 'reference', ClockCorrection(offset_ns=0)
        self.frozen = False
        """``freeze``: every correction stays as it is; no window is fitted."""
        self.ended = False
        """The recording has ended (``Offline.finish``): windows are fitted as far as its end allows."""
        self._peak = 0

    # -- the rig --------------------------------------------------------------------------------

    @property
    def topics(self) -> list[str]:
        """Every stream, the reference among them."""
        return list(self._streams)

    @property
    def streams(self) -> list[CameraStream]:
        return list(self._streams.values())

    @property
    def cameras(self) -> list[CameraStream]:
        """Every stream but the reference's."""
        return [s for s in self._streams.values() if s.topic != self.reference]

    def stream(self, topic: str) -> CameraStream:
        """The stream of ``topic``; StreamError for one not tracked."""
        s = self._streams.get(topic)
        if s is None:
            raise StreamError(f'{topic!r} is not a stream of this synchronisation')
        return s

    # -- operating (any thread) -----------------------------------------------------------------

    def seed(self, fit: CameraFit) -> None:
        """Correct ``fit.topic`` with a saved estimate (its latency delta included, as ``correction``
        gives it) until its own estimate is accepted (then locked; replaced and counted in
        ``seeds_replaced`` when they disagree). StreamError for a topic that is not a camera of this rig."""
        if fit.topic not in self._streams or fit.topic == self.reference:
            raise StreamError(f'{fit.topic}: not a camera of this rig to seed (reference {self.reference}, '
                              f'topics {sorted(self._streams)})')
        with self.lock:
            self._streams[fit.topic].lock.seed(replace(fit, offset_ns=fit.offset_ns - self.latency_delta_ns[fit.topic]))

    def retune(self, *, min_confidence: float) -> None:
        """Change the refined estimator's least share of agreeing windows (from the next decision on);
        ParameterError when it is not in [0, 1]."""
        refined = replace(self.params.refined, min_confidence=min_confidence)
        with self.lock:
            self.params = replace(self.params, refined=refined)

    def freeze(self, on: bool) -> None:
        """Keep every correction as it is and fit nothing (``on``), or go on estimating."""
        with self.lock:
            self.frozen = on

    def reacquire(self) -> None:
        """Forget every camera's decision and correction and estimate again from the bins held (a
        freeze ends too)."""
        with self.lock:
            self.frozen = False
            for s in self.cameras:
                self.forget(s, State.WAITING if s.bins.last_ns is None else State.ESTIMATING, 'reacquiring on request')

    def saved(self) -> dict[str, CameraFit]:
        """The estimate in force of each camera that has one (``report.saved``)."""
        with self.lock:
            return report.saved(self)

    def set_model(self, topic: str, model: str) -> None:
        """What tells ``topic``'s camera model apart (its message type, encoding and geometry): a camera
        of another model than the reference's, whose latency is not known, carries
        ``refined.MODEL_SYSTEMATIC_NS`` more error (they respond to one edge at different times)."""
        with self.lock:
            self.stream(topic).model = model
            ref_model = self._streams[self.reference].model
            for s in self.cameras:
                if s.model and ref_model:
                    s.known = replace(s.known, systematic_ns=model_systematic(
                        s.model, ref_model, latency_known=s.topic in self._latency_known))

    # -- feeding (any thread) -------------------------------------------------------------------

    def add(self, topic: str, times: TimeArray, receipt_ns: int | None, *, lo: int | None = None,
            hi: int | None = None) -> bool:
        """Bin one message's event times (``receipt_ns``: when it arrived, on the one clock the feeder
        has for every stream; None: not known, as for arrays); False when the message showed a clock
        jump (the stream starts over). ``lo``, ``hi``: the least and greatest of ``times``, when the
        feeder has them. StreamError for a topic not tracked."""
        with self.lock:
            return feed.add_times(self, self.stream(topic), times, receipt_ns, lo, hi)

    def add_bins(self, topic: str, m: MessageBins) -> bool:
        """``add`` for a message already counted on this engine's grid (``MessageBins.of`` with
        ``params.grid_ns``: what a camera process sends). Far events are judged by their bin."""
        with self.lock:
            return feed.add_bins(self, self.stream(topic), m)

    def forget(self, s: CameraStream, state: State, message: str, *, reset: bool = False) -> None:
        """A stream's decision and windows dropped (``reset``: its bins and lag line too: its clock jumped)."""
        if reset:
            s.reset(state, message)
        else:
            s.forget(state, message)
        self.method.forget(s.topic)

    # -- estimating (a timer's thread) ------------------------------------------------------------

    def step(self, now_ns: int | None = None) -> int:
        """Plan every camera's windows that are ready, fit them, decide and apply (the driver's part);
        returns how many windows were fitted. ``now_ns``: the feeder's clock, for silence. Counts are
        copied under the lock; fits and decisions run outside it, by the runner, so that ``add`` waits
        only for the copies."""
        with self.lock:
            self.driver.tick(self, now_ns)
            jobs = [] if self.frozen else [job for s in self.cameras for job in self.driver.jobs(self, s)]
            self._trim()  # after the windows planned took their copies
        fitted = self.fit(jobs)
        self.driver.after_step(self, fitted)
        return len(jobs)

    def fit(self, jobs: list[Job]) -> list[CameraStream]:
        """``jobs`` fitted by the runner and taken into their cameras' windows (a stale one, of a stream
        that jumped meanwhile, dropped); the cameras that took one."""
        with self.lock:
            calls = [(self.method.params(self, job), job, self.driver.keeps_curves) for job in jobs]
        found = self.runner.run(self.method.fit, calls)
        took: dict[str, CameraStream] = {}
        with self.lock:
            for job, fit in zip(jobs, found):
                s = self._streams[job.topic]
                if job.generation == s.generation:
                    self.method.take(self, s, job, fit)
                    took[s.topic] = s
        return list(took.values())

    def finish(self) -> dict[str, CameraFit]:
        """The recording has ended: each camera's decision over all its windows (``Offline.finish``).
        StreamError when the driver is live (a stream does not end) or a stream had no event."""
        end = getattr(self.driver, 'finish', None)
        if end is None:
            raise StreamError('a live engine has no end to finish at (drivers.Offline reads a recording whole)')
        found: dict[str, CameraFit] = end(self)
        return found

    def _trim(self) -> None:
        self.note_peak()  # before any is freed
        keep = self.driver.keep_ns(self)
        floors = self.method.floors(self) if not self.driver.places_alongside else {}
        for s in self._streams.values():
            if s.bins.last_ns is not None:
                s.bins.drop_before(min(s.bins.last_ns - keep, floors.get(s.topic, s.bins.last_ns)))

    def note_peak(self) -> None:
        """The most bytes of bins held so far, noted before any is freed."""
        self._peak = self.peak_nbytes

    # -- placement (``placement``) ------------------------------------------------------------------

    def prior(self, topic: str) -> int | None:
        """Where the windows of ``topic`` are searched before a line is accepted (``placement.prior``)."""
        return placement.prior(self, self.stream(topic))

    def arrival_prior(self, topic: str) -> int | None:
        """Where the arrival times of ``topic`` put it (``placement.arrival_prior``)."""
        return placement.arrival_prior(self, self.stream(topic))

    def said(self, topic: str, own: CameraFit, other: CameraFit | None = None) -> CameraFit:
        """A decision with what placed it said (``placement.said``)."""
        return placement.said(self, self.stream(topic), own, other)

    def centre(self, s: CameraStream) -> int | None:
        return placement.centre(self, s)

    def alt(self, s: CameraStream, w: Windows) -> Alt | None:
        return placement.alt(self, s, w)

    def kept(self, s: CameraStream, fits: dict[tuple[int, int], WindowFit]) -> dict[tuple[int, int], WindowFit]:
        """The windows of ``fits`` a decision is found from (``decide.since_step``)."""
        prior = self.centre(s)
        back = s.since_ns + prior if s.since_ns != s.first_ns and s.since_ns is not None and prior is not None else None
        return since_step(fits, restart_ns=s.restart_ns, back_ns=back)

    def restart(self, s: CameraStream, at_ns: int, by_ns: int | None) -> None:
        """A camera's clock stepped: its line starts again from ``at_ns`` (reference timeline), on
        windows short again, and its correction goes (a step is a new line, not a move of the old one)."""
        s.restart_ns = at_ns
        self.method.restart(s.topic, at_ns)
        what = f'clock stepped by {by_ns / 1e6:+.3f} ms' if by_ns is not None else 'clock stepped'
        s.lock.forget(State.ESTIMATING, f'{what}; re-acquiring')
        s.lock.note = what

    # -- reading (any thread) -------------------------------------------------------------------

    def paper_estimate(self, topic: str) -> PaperEstimate | None:
        """The paper's loop's outcome for a camera (None: no window tried, or the refined method)."""
        outcome = getattr(self.method, 'outcome', None)
        return outcome(topic) if outcome is not None else None

    @property
    def done(self) -> bool:
        """Nothing later in the recording can change a decision: a reader may stop (the paper's loop
        has ended for every camera; never for the refined method, which uses every window)."""
        return self.method.done(self)

    def correction(self, topic: str) -> ClockCorrection | None:
        """The correction a camera's messages get now, its known latency taken out (None: not locked
        since the last jump)."""
        return self._streams[topic].lock.published(self.latency_delta_ns[topic])

    def state(self, topic: str) -> State:
        return self._streams[topic].lock.state

    def status(self, topic: str, now_ns: int | None = None) -> Status:
        """What a front end reports of ``topic`` (``report.status``)."""
        with self.lock:
            return report.status(self, topic, now_ns)

    @property
    def nbytes(self) -> int:
        """Bytes of bins held now, every stream together."""
        return sum(s.bins.nbytes for s in self._streams.values())

    @property
    def peak_nbytes(self) -> int:
        """The most bytes of bins held at once so far, every stream together (noted before bins go)."""
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
        each keeps the driver's span behind its newest event, grows by a period between two steps,
        reaches at most ``jump_ns`` past its lag (later times are counted as far), and holds whole blocks."""
        span = self.driver.keep_ns(self) + step_period_ns + self.params.jump_ns
        return len(self._streams) * BinnedStream.ceiling_bytes(span, self.params.grid_ns)


def _checked_latencies(latencies_ns: Mapping[str, int] | None, *, topics: list[str], reference: str
                       ) -> dict[str, int]:
    latencies_ns = dict(latencies_ns or {})
    for topic, value in latencies_ns.items():
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or abs(value) > LATENCY_LIMIT_NS:
            raise ParameterError(f'latency of {topic} must be whole nanoseconds within +-1 s, got {value!r}')
    return latency_deltas(latencies_ns, topics=topics, reference=reference)
