"""A recording read whole through the engine: the offline driver that the array API and the bag tools
share. numpy only. The feeder reads the recording (once, and again for a camera whose line shows a
skew); the engine decides (docs/method.md, "What only offline does")."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace

import numpy as np

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine.engine import Engine
from evsync_ros.core.engine.params import LIVE_SEARCH_NS, OnlineParams
from evsync_ros.core.engine.windows import Known
from evsync_ros.core.paper import PaperEstimate, PaperParams
from evsync_ros.core.refined import RefinedParams, deskew_of
from evsync_ros.core.results import CameraFit, Method

__all__ = ['STEP_EVERY', 'Feeder', 'Offline', 'estimate', 'estimate_paper']

STEP_EVERY = 64
"""Messages between two fits of the windows that are ready (memory follows the window, not the recording)."""


class Feeder:
    """What a reader hands each message to: the engine, stepped as it goes (``stepping``: every
    ``STEP_EVERY`` messages, fitting what is ready and freeing bins; a reader whose messages do not
    come in arrival order, as arrays fed stream by stream, steps only at the end)."""

    def __init__(self, engine: Engine, *, stepping: bool = True) -> None:
        self.engine = engine
        self.stepping = stepping
        self._topics = set(engine.topics)
        self._messages = 0
        self._modelled: set[str] = set()

    def add(self, topic: str, times: np.ndarray, arrival_ns: int | None = None, model: str = '', *,
            lo: int | None = None, hi: int | None = None) -> None:
        """One message: its event times, when it arrived (None: not known), what model its camera is;
        ``lo``, ``hi``: the least and greatest time, when the reader has them (``Engine.add``). A topic
        the engine does not estimate (a second read's) is passed over."""
        if topic not in self._topics:
            return
        if model and topic not in self._modelled:
            self._modelled.add(topic)
            self.engine.set_model(topic, model)
        self.engine.add(topic, times, arrival_ns, lo=lo, hi=hi)
        self._messages += 1
        if self.stepping and self._messages % STEP_EVERY == 0:
            self.engine.step(decide=False)

    @property
    def peak_nbytes(self) -> int:
        """The most bytes of bins the engine has held at once (``Engine.peak_nbytes``)."""
        return self.engine.peak_nbytes

    @property
    def done(self) -> bool:
        """Nothing later in the recording can change a decision (``Engine.done``): the reader may stop."""
        return self.engine.done


Read = Callable[[Feeder, bool], None]
"""Reads the recording into a feeder; the flag: a second read (for the skewed cameras)."""


@dataclass(frozen=True)
class Offline:
    """What an offline estimate found."""

    cameras: dict[str, CameraFit]
    passes: int
    binned: dict[str, ClockCorrection]
    """Per camera whose decision is a second read's, the skew its windows were binned through (their
    offsets are on that de-skewed timeline); a camera not here was binned as recorded."""
    engine: Engine
    """The first read's engine (what the streams held: spans, far and late events)."""

    def paper(self) -> dict[str, PaperEstimate]:
        """The paper's method: each camera's loop (the windows it tried and the one it kept)."""
        found = {t: self.engine.paper_estimate(t) for t in self.cameras}
        return {t: e for t, e in found.items() if e is not None}


def estimate(read: Read, topics: Iterable[str], *, reference: str, params: RefinedParams = RefinedParams(),
             arrivals: bool = True, in_order: bool = True, latencies_ns: Mapping[str, int] | None = None,
             priors_ns: Mapping[str, int] | None = None, known: Mapping[str, Known] | None = None) -> Offline:
    """Every camera against ``reference`` by the refined method, from one read of the recording, and a
    second for the cameras whose accepted line shows a skew (their times binned with it taken out,
    their windows centred on the line; the second decision is kept when accepted, or when the first
    was not). ``arrivals``: the reader gives arrival times, whose prior is searched as narrowly as
    the live node searches (``LIVE_SEARCH_NS``); without them, the first events' prior over
    ``params.max_shift_ns``. ``in_order``: the reader gives the messages in the order they arrived
    (else the engine fits nothing until the read ends). ``priors_ns``, ``known``: per camera, a
    prior and what its decision knows (a systematic error)."""
    topics = list(topics)
    if arrivals:
        params = replace(params, max_shift_ns=min(params.max_shift_ns, LIVE_SEARCH_NS))
    online = OnlineParams(refined=params)
    engine = Engine(topics, reference=reference, params=online, latencies_ns=latencies_ns, offline=True,
                    priors_ns=priors_ns, known=known)
    read(Feeder(engine, stepping=in_order), False)
    cameras = engine.finish()
    deskews = {t: d for t, c in cameras.items() if (d := deskew_of(c)) is not None}
    if not deskews:
        return Offline(cameras, 1, {}, engine)
    knowns = {t: replace(engine.known(t), skew_ppm=d.skew_ppm, anchor_ns=d.anchor_ns,
                         skew_se_ppm=cameras[t].skew_uncertainty_ppm or math.inf) for t, d in deskews.items()}
    again = Engine([reference, *deskews], reference=reference, params=online, latencies_ns=latencies_ns,
                   offline=True, priors_ns={t: cameras[t].offset_ns for t in deskews}, corrections=deskews,
                   known=knowns)
    read(Feeder(again, stepping=in_order), True)
    binned = {}
    for topic, second in again.finish().items():
        if second.accepted or not cameras[topic].accepted:
            cameras[topic], binned[topic] = second, deskews[topic]
    return Offline(cameras, 2, binned, engine)


def estimate_paper(read: Read, topics: Iterable[str], *, reference: str, params: PaperParams = PaperParams(),
                   in_order: bool = True) -> Offline:
    """Every camera against ``reference`` by the paper's loop (``Engine`` with the paper's method),
    from one read of the recording, which may stop early once every camera's loop has ended
    (``Feeder.done``). The prior that places each camera's windows is its arrival times', where the
    reader gives them, else its first events' (the paper's: each stream from its own start)."""
    engine = Engine(list(topics), reference=reference, params=OnlineParams(method=Method.PAPER, paper=params),
                    offline=True)
    read(Feeder(engine, stepping=in_order), False)
    return Offline(engine.finish(), 1, {}, engine)
