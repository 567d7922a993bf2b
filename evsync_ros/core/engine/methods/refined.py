"""The refined method in the engine: each camera's windows planned on the ladder (``plan.window_jobs``),
fitted to microseconds (``refined.fit_window``), and decided by agreement (``decide``); beside them,
live, the windows its events alone place (``evidence``). numpy only."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from evsync_ros.core.density import TIME_LIMIT_NS
from evsync_ros.core.engine.decide import clearer, decide, on_stretch, stretch_of, with_whole
from evsync_ros.core.engine.evidence import voted_params
from evsync_ros.core.engine.methods.base import Decision
from evsync_ros.core.engine.params import EngineParams
from evsync_ros.core.engine.plan import Window, from_start, stretch_jobs, window_jobs
from evsync_ros.core.engine.stream import CameraStream, Job
from evsync_ros.core.refined import fit_window
from evsync_ros.core.results import CameraFit, WindowFit

if TYPE_CHECKING:
    from evsync_ros.core.engine.engine import Engine

__all__ = ['Alt', 'Refined', 'fit']

Key = tuple[int, int]
"""A window: (start on the reference's timeline, length)."""


def fit(params: EngineParams, job: Job, whole: bool) -> WindowFit:
    """One window fitted (``whole``: with its curve and counts, else ``WindowFit.light``); what the
    runner is handed, with the parameters of the window's placement (``Refined.params``)."""
    found = fit_window(job.ref, job.cam, ref_start_ns=job.start_ns, length_ns=job.length_ns, prior_ns=job.prior_ns,
                       params=params.refined)
    return found if whole else found.light()


@dataclass
class Alt:
    """A camera's windows placed by its events alone, fitted beside its own while its decision under
    the arrival prior does not stand (live; ``evidence``)."""

    centre_ns: int
    """Where they are searched: its first events against the reference's, then their accepted line."""
    fits: dict[Key, WindowFit] = field(default_factory=dict)
    estimate: CameraFit | None = None
    voted: bool = False
    """Placed on where their peaks point (``evidence.vote``) and searched narrowly about it."""
    refused: tuple[int, ...] = ()
    """Offsets voted before whose narrow search was refused: not voted for again."""


@dataclass
class Windows:
    """What the refined method keeps of one camera."""

    own: dict[Key, WindowFit] = field(default_factory=dict)
    """Its windows fitted as ``Engine.centre`` places them, light."""
    decision: CameraFit | None = None
    """Their newest decision (live)."""
    alt: Alt | None = None
    whole: WindowFit | None = None
    """The most confident window with its curve and counts (what a report draws; offline)."""
    stretch: tuple[tuple[tuple[int, int], int], CameraFit] | None = None
    """((stretch, generation), its decision): a decision refused for quiet windows outside a stretch,
    decided again on that stretch alone (``stretched``)."""


class Refined:
    """The refined method's windows and decisions for every camera of an engine."""

    fit = staticmethod(fit)

    def __init__(self) -> None:
        self.cameras: dict[str, Windows] = {}

    def of(self, topic: str) -> Windows:
        return self.cameras.setdefault(topic, Windows())

    def forget(self, topic: str) -> None:
        """A camera's windows and decisions dropped (its clock jumped, or it re-acquires)."""
        self.cameras[topic] = Windows()

    def jobs(self, e: Engine, s: CameraStream) -> list[Job]:
        """The camera's windows whose data are complete and that have not been fitted, and those its
        events alone place while they are needed (``Engine.alt``)."""
        prior = e.centre(s)
        if prior is None:
            return []
        w = self.of(s.topic)
        out = self._planned(e, s, e.params, prior, w.own, alt=False)
        alt = e.alt(s, w)
        if alt is not None:
            out += self._planned(e, s, self.alt_params(e, alt), alt.centre_ns, alt.fits, alt=True)
        return out

    @staticmethod
    def _planned(e: Engine, s: CameraStream, p: EngineParams, prior: int, fitted: dict[Key, WindowFit], *,
                 alt: bool) -> list[Job]:
        ref = e.stream(e.reference)
        found = window_jobs(p, ref.bins, s.bins, ref_since=ref.since_ns, cam_since=s.since_ns, prior=prior,
                            restart=s.restart_ns, resumed=s.since_ns != s.first_ns, fitted=fitted,
                            ended=e.ended or s.silent)
        return [Job(s.generation, s.topic, alt, *window) for window in found]

    def take(self, e: Engine, s: CameraStream, job: Job, found: object) -> None:
        """A window fitted, into the camera's windows (light; the clearest kept whole for the report)."""
        assert isinstance(found, WindowFit)
        w = self.of(s.topic)
        key = (found.ref_start_ns, found.length_ns)
        if job.alt:
            if w.alt is not None:
                w.alt.fits[key] = found.light()
            return
        s.tried += 1
        if found.ncc.size and clearer(found, w.whole):
            w.whole = found
        w.own[key] = found.light()

    def at_end(self, e: Engine, s: CameraStream) -> list[Job]:
        """A recording shorter than one whole window: its one window from the reference's start (none
        where the prior is further than any two times can be apart: corrupt arrival lags)."""
        ref, prior = e.stream(e.reference), e.centre(s)
        if self.of(s.topic).own or prior is None or ref.since_ns is None or abs(prior) > 2 * TIME_LIMIT_NS:
            return []
        return [Job(s.generation, s.topic, False, *from_start(e.params, ref.bins, s.bins, ref_since=ref.since_ns,
                                                              prior=prior))]

    def decide(self, e: Engine, streams: Iterable[CameraStream]) -> list[Decision]:
        """Each camera's decision from its windows since its last step (``Engine.kept``), and its
        events-placed windows' where it has them."""
        with e.lock:
            asked = []
            for s in streams:
                w = self.of(s.topic)
                w.own = e.kept(s, w.own)
                if w.alt is not None:
                    w.alt.fits = e.kept(s, w.alt.fits)
                alt = list(w.alt.fits.values()) if w.alt is not None else []
                if w.own or alt:
                    asked.append((s, s.generation, s.lock.correction, list(w.own.values()), alt))
            params = e.params.refined
            wide = {s.topic: self.alt_params(e, self.of(s.topic).alt).refined for s, *_, alt in asked if alt}
        found = e.runner.run(decide, [(s.topic, fits, params, s.known) for s, _, _, fits, _ in asked]
                             + [(s.topic, alt, wide[s.topic], s.known) for s, *_, alt in asked if alt])
        alts = iter(found[len(asked):])
        return [Decision(s, generation, correction, self.stretched(e, s, own), next(alts) if alt else None)
                for (s, generation, correction, _, alt), own in zip(asked, found)]

    def params(self, e: Engine, job: Job) -> EngineParams:
        """The parameters a job is fitted with: its placement's."""
        return self.alt_params(e, self.of(job.topic).alt) if job.alt else e.params

    @staticmethod
    def alt_params(e: Engine, alt: Alt | None) -> EngineParams:
        """The search of a camera's events-placed windows: the full range, or narrow about where their
        peaks point (``evidence.voted_params``)."""
        p = e.params
        if alt is not None and alt.voted:
            return replace(p, refined=voted_params(p.refined, narrow_ns=p.refined.max_shift_ns,
                                                   wide_ns=p.events_shift_ns))
        return p.shifted(p.events_shift_ns)

    def floors(self, e: Engine) -> dict[str, int]:
        """No bins held for windows still to try beyond those the engine keeps."""
        return {}

    def done(self, e: Engine) -> bool:
        """Never: every window counts."""
        return False

    def ended(self, topic: str) -> bool:
        """Never: a camera's windows go on."""
        return False

    def note(self, s: CameraStream, own: CameraFit, alt: CameraFit | None) -> None:
        """A camera's newest decisions kept (its own, which says whether its events-placed windows are
        still needed, and theirs)."""
        w = self.of(s.topic)
        w.decision = own
        if w.alt is not None and alt is not None:
            w.alt.estimate = alt

    def finished(self, s: CameraStream, fit: CameraFit) -> CameraFit:
        """A decision read whole: its clearest window with its curve and counts, for the report."""
        return replace(fit, windows=with_whole(fit.windows, self.of(s.topic).whole))

    def restart(self, topic: str, at_ns: int) -> None:
        """The camera's windows from ``at_ns`` on only (its clock stepped)."""
        w = self.of(topic)
        w.own = {k: f for k, f in w.own.items() if k[0] >= at_ns}

    def stretched(self, e: Engine, s: CameraStream, est: CameraFit) -> CameraFit:
        """``est``, or when it is refused only for quiet windows outside a stretch, decided again on
        that stretch's own windows (``decide.on_stretch``); the stretch's decision is kept while the
        stretch and the stream's generation stay."""
        span = stretch_of(est)
        if span is None:
            return est
        w, key = self.of(s.topic), (span, s.generation)
        if w.stretch is None or w.stretch[0] != key:
            with e.lock:
                ref, prior = e.stream(e.reference), e.centre(s)
                found: list[Window] = [] if prior is None else stretch_jobs(
                    e.params, ref.bins, s.bins, span, prior=prior, longer_ns=min(f.length_ns for f in est.windows))
            if not found:
                return est
            fits = e.runner.run(fit, [(e.params, Job(s.generation, s.topic, False, *x), False) for x in found])
            w.stretch = (key, decide(s.topic, fits, e.params.refined, s.known))
        return on_stretch(est, w.stretch[1])
