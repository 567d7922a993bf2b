"""The paper's method in the engine: each camera's loop (windows of T one after another from where both
streams begin, the camera's moved by the prior the loop began with, until one is accepted: docs/method.md,
"The paper's method"), the same for every front end. numpy only."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from evsync_ros.core.bins import BinnedStream
from evsync_ros.core.engine.methods.base import Decision
from evsync_ros.core.engine.params import EngineParams
from evsync_ros.core.engine.plan import Window, paper_job, paper_jobs
from evsync_ros.core.engine.stream import CameraStream, Job
from evsync_ros.core.paper import PaperEstimate, WindowResult, estimate_window_counts
from evsync_ros.core.results import CameraFit

if TYPE_CHECKING:
    from evsync_ros.core.engine.engine import Engine

__all__ = ['Paper', 'PaperLoop', 'fit']


def fit(params: EngineParams, job: Job, whole: bool) -> WindowResult:
    """One window of the loop (what the runner is handed; ``whole`` is the refined method's)."""
    n, tau = params.paper.n_bins, params.paper.tau_ns
    return estimate_window_counts(job.ref.counts(job.start_ns, tau, n),
                                  job.cam.counts(job.start_ns - job.prior_ns, tau, n), ref_start_ns=job.start_ns,
                                  cam_start_ns=job.start_ns - job.prior_ns, index=job.number, params=params.paper)


@dataclass
class PaperLoop:
    """One camera's loop: where its windows start, the prior they keep, the next to try, those tried."""

    origin_ns: int | None = None
    """Start of window 0 on the reference's timeline: where both streams have begun (on the grid)."""
    prior_ns: int = 0
    """The camera's prior when the loop began: every window of the camera is the reference's moved
    by it (the paper pairs windows by fixed starts)."""
    next_k: int = 0
    windows: list[WindowResult] = field(default_factory=list)
    new: bool = False
    """A window was taken since the last decision."""

    @property
    def done(self) -> bool:
        """A window was accepted: the loop has ended."""
        return bool(self.windows) and self.windows[-1].accepted

    def begin(self, ref: BinnedStream, cam: BinnedStream, *, ref_since: int | None, cam_since: int | None,
              prior: int) -> None:
        """Window 0's start, fixed with the prior on the first call that has both streams begun: where
        both have begun and have bins held, on the grid."""
        if self.origin_ns is None and ref_since is not None and cam_since is not None:
            start = max(ref_since, cam_since + prior)
            for held, moved in ((ref.held_from_ns, 0), (cam.held_from_ns, prior)):
                start = start if held is None else max(start, held + moved)  # not a window freed in part
            self.origin_ns, self.prior_ns = start - start % ref.grid_ns, prior

    def next_windows(self, p: EngineParams, ref: BinnedStream, cam: BinnedStream) -> list[tuple[int, Window]]:
        """Its windows whose data both streams have passed (``plan.paper_jobs``), with their numbers; none
        once it ended."""
        if self.done or self.origin_ns is None:
            return []
        found, self.next_k = paper_jobs(p, ref, cam, origin=self.origin_ns, prior=self.prior_ns, k=self.next_k)
        return found

    def floor(self, window_ns: int) -> tuple[int, int] | None:
        """Where the bins of the windows it has still to try begin, on the reference's and the
        camera's timelines (None: it has ended or not begun). A loop that has tried nothing may yet
        fit its window 0 at the end of a recording."""
        if self.done or self.origin_ns is None:
            return None
        w = self.origin_ns + (self.next_k if self.windows else 0) * window_ns
        return w, w - self.prior_ns

    def take(self, found: WindowResult) -> bool:
        """A window fitted, in order; False when the loop had ended (a later window of a batch)."""
        if self.done:
            return False
        self.windows.append(found)
        self.new = True
        return True

    def outcome(self) -> PaperEstimate | None:
        """The loop's outcome so far (None: no window tried)."""
        return PaperEstimate.of(self.windows) if self.windows else None


class Paper:
    """The paper's loop of every camera of an engine."""

    fit = staticmethod(fit)

    def __init__(self) -> None:
        self.loops: dict[str, PaperLoop] = {}

    def of(self, topic: str) -> PaperLoop:
        return self.loops.setdefault(topic, PaperLoop())

    def forget(self, topic: str) -> None:
        self.loops[topic] = PaperLoop()

    def jobs(self, e: Engine, s: CameraStream) -> list[Job]:
        """The loop's next windows, until one is accepted (it begins with the camera's prior then)."""
        prior = e.centre(s)
        if prior is None:
            return []
        ref, loop = e.stream(e.reference), self.of(s.topic)
        loop.begin(ref.bins, s.bins, ref_since=ref.since_ns, cam_since=s.since_ns, prior=prior)
        return [Job(s.generation, s.topic, False, *w, number=k)
                for k, w in loop.next_windows(e.params, ref.bins, s.bins)]

    def take(self, e: Engine, s: CameraStream, job: Job, found: object) -> None:
        assert isinstance(found, WindowResult)
        if self.of(s.topic).take(found):
            s.tried += 1
            s.accepted += found.accepted

    def at_end(self, e: Engine, s: CameraStream) -> list[Job]:
        """A recording shorter than its window: the loop's one partial window 0."""
        ref, prior, loop = e.stream(e.reference), e.centre(s), self.of(s.topic)
        if loop.windows:
            return []
        if prior is not None:
            loop.begin(ref.bins, s.bins, ref_since=ref.since_ns, cam_since=s.since_ns, prior=prior)
        if loop.origin_ns is None:
            return []
        return [Job(s.generation, s.topic, False,
                    *paper_job(ref.bins, s.bins, loop.origin_ns, e.params.window_ns, loop.prior_ns))]

    def decide(self, e: Engine, streams: Iterable[CameraStream]) -> list[Decision]:
        """Each camera whose loop took a window: its outcome so far, in the contract's form."""
        out = []
        with e.lock:
            for s in streams:
                loop = self.of(s.topic)
                outcome = loop.outcome()
                if loop.new and outcome is not None:
                    loop.new = False
                    out.append(Decision(s, s.generation, s.lock.correction,
                                        outcome.as_camera(s.topic, params=e.params.paper)))
        return out

    def floors(self, e: Engine) -> dict[str, int]:
        """Per stream, where the bins its loops have still to try begin (``PaperLoop.floor``)."""
        floors: dict[str, int] = {}
        for topic, loop in self.loops.items():
            floor = loop.floor(e.params.window_ns)
            if floor is not None:
                floors[e.reference] = min(floors.get(e.reference, floor[0]), floor[0])
                floors[topic] = floor[1]
        return floors

    def done(self, e: Engine) -> bool:
        """Every camera's loop has ended: nothing later in the recording can change a decision."""
        return all(self.of(t).done for t in e.topics if t != e.reference)

    def params(self, e: Engine, job: Job) -> EngineParams:
        return e.params

    def ended(self, topic: str) -> bool:
        """The camera's loop has ended (a window was accepted)."""
        return topic in self.loops and self.loops[topic].done

    def note(self, s: CameraStream, own: CameraFit, alt: CameraFit | None) -> None:
        """Nothing beyond the loop."""

    def finished(self, s: CameraStream, fit: CameraFit) -> CameraFit:
        return fit

    def restart(self, topic: str, at_ns: int) -> None:
        """The loop has no line to restart."""

    def outcome(self, topic: str) -> PaperEstimate | None:
        return self.of(topic).outcome() if topic in self.loops else None
