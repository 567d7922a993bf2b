"""The paper's loop for one camera, as the engine runs it for every front end: windows of T one
after another from where both streams begin, the camera's moved by the prior the loop began with,
until one is accepted (docs/method.md, "The paper's method"). numpy only."""

from __future__ import annotations

from dataclasses import dataclass, field

from evsync_ros.core.bins import BinnedStream
from evsync_ros.core.engine.params import OnlineParams
from evsync_ros.core.engine.plan import Job, paper_job, paper_jobs
from evsync_ros.core.paper import PaperEstimate, WindowResult

__all__ = ['PaperLoop']


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

    @property
    def done(self) -> bool:
        """A window was accepted: the loop has ended."""
        return bool(self.windows) and self.windows[-1].accepted

    def begin(self, ref: BinnedStream, cam: BinnedStream, *, ref_since: int | None, cam_since: int | None,
              prior: int) -> int | None:
        """Window 0's start, fixed with the prior on the first call that has both streams begun: where
        both have begun and have bins held, on the grid (None: one has not begun)."""
        if self.origin_ns is None and ref_since is not None and cam_since is not None:
            start = max(ref_since, cam_since + prior)
            for held, moved in ((ref.held_from_ns, 0), (cam.held_from_ns, prior)):
                start = start if held is None else max(start, held + moved)  # not a window freed in part
            self.origin_ns, self.prior_ns = start - start % ref.grid_ns, prior
        return self.origin_ns

    def next_jobs(self, p: OnlineParams, ref: BinnedStream, cam: BinnedStream) -> list[Job]:
        """Its windows whose data both streams have passed (``plan.paper_jobs``), none once it ended."""
        if self.done or self.origin_ns is None:
            return []
        jobs, self.next_k = paper_jobs(p, ref, cam, origin=self.origin_ns, prior=self.prior_ns, k=self.next_k)
        return [job for _, job in jobs]

    def first_job(self, p: OnlineParams, ref: BinnedStream, cam: BinnedStream) -> Job | None:
        """Window 0, whole or not: a recording shorter than T gets its one partial window."""
        return None if self.origin_ns is None else paper_job(ref, cam, self.origin_ns, p.window_ns, self.prior_ns)

    def floor(self, window_ns: int) -> tuple[int, int] | None:
        """Where the bins of the windows it has still to try begin, on the reference's and the
        camera's timelines (None: it has ended or not begun). A loop that has tried nothing may yet
        fit its window 0 at the end of a recording."""
        if self.done or self.origin_ns is None:
            return None
        w = self.origin_ns + (self.next_k if self.windows else 0) * window_ns
        return w, w - self.prior_ns

    def index(self, w: int, window_ns: int) -> int:
        """The number of its window starting at ``w`` (0 before it began)."""
        return 0 if self.origin_ns is None else (w - self.origin_ns) // window_ns

    def take(self, fit: WindowResult) -> PaperEstimate | None:
        """Add a window fitted, in order, and give the loop's outcome with it; None when the loop had
        ended (a later window of a batch, not taken)."""
        if self.done:
            return None
        self.windows.append(fit)
        return self.outcome()

    def outcome(self) -> PaperEstimate | None:
        """The loop's outcome so far (None: no window tried)."""
        return PaperEstimate.of(self.windows) if self.windows else None
