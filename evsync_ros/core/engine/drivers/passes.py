"""A recording read whole through the engine, as the array API and the bag tools read it: the reads the
offline driver makes (a first; one more for the cameras its events alone must place; one more for the
skewed and re-placed ones) and the feeder each read goes through (docs/method.md, "What only offline
does"). numpy only."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine.drivers.offline import Offline
from evsync_ros.core.engine.engine import Engine
from evsync_ros.core.engine.evidence import RECENTRE_NS, may_vote, settled, vote, voted_params
from evsync_ros.core.engine.params import LIVE_SEARCH_NS, EngineParams
from evsync_ros.core.engine.stream import Known
from evsync_ros.core.paper import PaperEstimate, PaperParams
from evsync_ros.core.refined import RefinedParams, deskew_of
from evsync_ros.core.results import CameraFit, Method, Prior, PriorChoice

__all__ = ['STEP_EVERY', 'Feeder', 'Found', 'Read', 'estimate', 'estimate_paper']

STEP_EVERY = 64
"""Messages between two fits of the windows that are ready (memory follows the window, not the recording)."""


class Feeder:
    """What a reader hands each message to: the engines of one read (each takes the topics it
    estimates), stepped as it goes (``stepping``: every ``STEP_EVERY`` messages, fitting what is ready
    and freeing bins; a reader whose messages do not come in arrival order, as arrays fed stream by
    stream, steps only at the end)."""

    def __init__(self, *engines: Engine, stepping: bool = True) -> None:
        self.engines = engines
        self.stepping = stepping
        self._messages = 0
        self._modelled: set[tuple[int, str]] = set()

    @property
    def engine(self) -> Engine:
        """The read's first engine."""
        return self.engines[0]

    @property
    def topics(self) -> list[str]:
        """Every topic an engine of this read estimates."""
        return list(dict.fromkeys(t for e in self.engines for t in e.topics))

    def add(self, topic: str, times: np.ndarray, arrival_ns: int | None = None, model: str = '', *,
            lo: int | None = None, hi: int | None = None) -> None:
        """One message: its event times, when it arrived (None: not known), what model its camera is;
        ``lo``, ``hi``: the least and greatest time, when the reader has them (``Engine.add``). A topic
        no engine estimates (a second read's) is passed over."""
        took = False
        for k, engine in enumerate(self.engines):
            if topic not in engine.topics:
                continue
            if model and (k, topic) not in self._modelled:
                self._modelled.add((k, topic))
                engine.set_model(topic, model)
            engine.add(topic, times, arrival_ns, lo=lo, hi=hi)
            took = True
        if not took:
            return
        self._messages += 1
        if self.stepping and self._messages % STEP_EVERY == 0:
            for engine in self.engines:
                engine.step()

    @property
    def peak_nbytes(self) -> int:
        """The most bytes of bins the engines have held at once (``Engine.peak_nbytes``)."""
        return sum(e.peak_nbytes for e in self.engines)

    @property
    def done(self) -> bool:
        """Nothing later in the recording can change a decision (``Engine.done``): the reader may stop."""
        return all(e.done for e in self.engines)


Read = Callable[[Feeder, bool], None]
"""Reads the recording into a feeder; the flag: a read after the first (only the feeder's topics)."""


@dataclass(frozen=True)
class Found:
    """What an offline estimate found."""

    cameras: dict[str, CameraFit]
    passes: int
    binned: dict[str, ClockCorrection]
    """Per camera whose decision is a later read's binned through a skew, that skew (their windows'
    offsets are on that de-skewed timeline); a camera not here was binned as recorded."""
    engine: Engine
    """The first read's engine (what the streams held: spans, far and late events)."""

    def paper(self) -> dict[str, PaperEstimate]:
        """The paper's method: each camera's loop (the windows it tried and the one it kept)."""
        found = {t: self.engine.paper_estimate(t) for t in self.cameras}
        return {t: e for t, e in found.items() if e is not None}


def estimate(read: Read, topics: Iterable[str], *, reference: str, params: RefinedParams = RefinedParams(),
             arrivals: bool = True, in_order: bool = True, latencies_ns: Mapping[str, int] | None = None,
             priors_ns: Mapping[str, int] | None = None, known: Mapping[str, Known] | None = None,
             prior: PriorChoice = PriorChoice.AUTO) -> Found:
    """Every camera against ``reference`` by the refined method, read whole (docs/method.md, "What only
    offline does"): a first read; one more for the cameras its arrival times placed without a decision
    that stands (their windows placed by their events alone, ``evidence.choose`` taking one); one more
    for the cameras still refused whose windows' peaks point at one offset (``evidence.vote``: searched
    narrowly about it); and one more for the cameras whose accepted line shows a skew (their times
    binned with it taken out) or lies far from where their windows were placed (``evidence.RECENTRE_NS``),
    their windows centred on the line (kept when accepted, or when the first was not).

    ``arrivals``: the reader gives arrival times, whose prior is searched as narrowly as the live node
    searches (``LIVE_SEARCH_NS``); without them, or with ``prior`` EVENTS, the first events' prior over
    ``params.max_shift_ns``. ``in_order``: the reader gives the messages in the order they arrived (else
    the engine fits nothing until the read ends). ``priors_ns``, ``known``: per camera, a prior (none
    of those is placed again) and what its decision knows (a systematic error)."""
    full = params.max_shift_ns
    online = EngineParams(refined=replace(params, max_shift_ns=min(full, LIVE_SEARCH_NS) if arrivals else full),
                          events_shift_ns=full, prior=prior)
    engine = Engine(list(topics), reference=reference, params=online, latencies_ns=latencies_ns, driver=Offline(),
                    priors_ns=priors_ns, known=known)
    read(Feeder(engine, stepping=in_order), False)
    run = _Reads(read, engine, engine.finish(), in_order=in_order, latencies_ns=latencies_ns,
                 fixed=set(priors_ns or ()))
    if arrivals and prior is PriorChoice.AUTO:
        run.by_events()
    if prior is not PriorChoice.ARRIVAL:
        run.by_vote(min(full, LIVE_SEARCH_NS))
    return run.again()


@dataclass
class _Reads:
    """The offline driver's reads after the first: each for the cameras that need it."""

    read: Read
    engine: Engine
    """The first read's."""
    cameras: dict[str, CameraFit]
    in_order: bool
    latencies_ns: Mapping[str, int] | None
    fixed: set[str]
    """Cameras the caller placed: never placed again."""
    reads: int = 1
    binned: dict[str, ClockCorrection] = field(default_factory=dict)
    wide: dict[str, CameraFit] = field(default_factory=dict)
    """The decisions of the windows placed by the events alone, where a read placed them so."""

    def _engines(self, groups: Mapping[str, tuple[EngineParams, int | None]], *,
                 corrections: Mapping[str, ClockCorrection] | None = None,
                 known: Mapping[str, Known] | None = None) -> list[Engine]:
        """One engine per distinct parameters of ``groups`` ({camera: (parameters, fixed prior)}), read
        together: each camera binned through its ``corrections``, knowing ``known`` (else the first read's)."""
        by: dict[EngineParams, list[str]] = {}
        for topic, (p, _) in groups.items():
            by.setdefault(p, []).append(topic)
        ref, e, known = self.engine.reference, self.engine, dict(known or {})
        engines = [Engine([ref, *ts], reference=ref, params=p, latencies_ns=self.latencies_ns, driver=Offline(),
                          priors_ns={t: v for t in ts if (v := groups[t][1]) is not None},
                          corrections={t: corrections[t] for t in ts if corrections and t in corrections},
                          known={t: known.get(t, e.known(t)) for t in ts}) for p, ts in by.items()]
        self.read(Feeder(*engines, stepping=self.in_order), True)
        self.reads += 1
        return engines

    def by_events(self) -> None:
        """The cameras whose decision under the arrival prior does not stand, placed by their events alone."""
        e = self.engine
        tried = [t for t, c in self.cameras.items()
                 if t not in self.fixed and not settled(c, e.arrival_prior(t), _last(e, t))]
        if tried:
            events = replace(e.params, prior=PriorChoice.EVENTS)
            (found,) = self._engines(dict.fromkeys(tried, (events, None)))
            for topic, fit in found.finish().items():
                self.wide[topic] = fit
                self.cameras[topic] = e.said(topic, self.cameras[topic], fit)

    def by_vote(self, narrow_ns: int) -> None:
        """The cameras still refused whose windows' peaks point at one offset (``evidence.vote``),
        searched narrowly about it, the chance judged over the wide range (``evidence.voted_params``)."""
        p = self.engine.params
        wide = {t: self.wide.get(t, c) for t, c in self.cameras.items() if t not in self.fixed and not c.accepted}
        voted = {t: v for t, c in wide.items() if may_vote(c)
                 and (v := vote(c.windows, lobe_ns=p.refined.lobe_margin_ns)) is not None}
        if not voted:
            return
        narrow = replace(p, refined=voted_params(p.refined, narrow_ns=narrow_ns, wide_ns=p.events_shift_ns))
        for engine in self._engines({t: (narrow, v) for t, v in voted.items()}):
            for topic, fit in engine.finish().items():
                if fit.accepted:
                    self.cameras[topic] = replace(fit, prior=Prior.EVENTS, prior_reason=(
                        f'placed by its events alone: its windows\' peaks point at {voted[topic] / 1e6:+.3f} ms, '
                        f'searched within {narrow_ns / 1e9:g} s of it; {self.cameras[topic].prior_reason}'))

    def again(self) -> Found:
        """The cameras whose accepted line shows a skew or lies far from where its windows were searched:
        their windows centred on the line, their times binned through the skew; each second decision
        kept when accepted, or when the first was not. The cameras its events alone placed are
        searched as widely as that placement was."""
        e, cams = self.engine, self.cameras
        again = {t: c for t, c in cams.items() if deskew_of(c) is not None or _far(c)}
        if not again:
            return Found(cams, self.reads, self.binned, e)
        deskews = {t: d for t, c in again.items() if (d := deskew_of(c)) is not None}
        known = {t: replace(e.known(t), skew_ppm=d.skew_ppm, anchor_ns=d.anchor_ns,
                            skew_se_ppm=cams[t].skew_uncertainty_ppm or math.inf) for t, d in deskews.items()}
        p = e.params
        groups = {t: (p.shifted(p.events_shift_ns if c.prior is Prior.EVENTS else p.refined.max_shift_ns),
                      c.offset_ns) for t, c in again.items()}
        for engine in self._engines(groups, corrections=deskews, known=known):
            for topic, second in engine.finish().items():
                first = cams[topic]
                if second.accepted or not first.accepted:
                    cams[topic] = replace(second, prior=first.prior, prior_reason=first.prior_reason)
                    if topic in deskews:
                        self.binned[topic] = deskews[topic]
        return Found(cams, self.reads, self.binned, e)


def _last(engine: Engine, topic: str) -> int:
    span = engine.first_last(topic)
    return span[1] if span is not None else 0


def _far(fit: CameraFit) -> bool:
    """An accepted line that lies more than ``RECENTRE_NS`` from where its agreeing windows were searched."""
    return fit.accepted and any(abs(w.offset_ns - w.prior_ns) > RECENTRE_NS for w in fit.windows if w.accepted)


def estimate_paper(read: Read, topics: Iterable[str], *, reference: str, params: PaperParams = PaperParams(),
                   in_order: bool = True, prior: PriorChoice = PriorChoice.AUTO) -> Found:
    """Every camera against ``reference`` by the paper's loop (``Engine`` with the paper's method),
    from one read of the recording, which may stop early once every camera's loop has ended
    (``Feeder.done``). The prior that places each camera's windows is its arrival times', where the
    reader gives them and ``prior`` is not EVENTS, else its first events' (the paper's: each stream from
    its own start)."""
    engine = Engine(list(topics), reference=reference,
                    params=EngineParams(method=Method.PAPER, paper=params, prior=prior), driver=Offline())
    read(Feeder(engine, stepping=in_order), False)
    return Found(engine.finish(), 1, {}, engine)
