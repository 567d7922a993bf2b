"""What the engine keeps of each stream, and what it reports of one. numpy only."""

from __future__ import annotations

from dataclasses import dataclass, field

from evsync_ros.core.bins import BinnedStream, GridCounts
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine.arrival import ArrivalTrack
from evsync_ros.core.engine.lock import CameraLock, State
from evsync_ros.core.engine.paperloop import PaperLoop
from evsync_ros.core.engine.windows import Known
from evsync_ros.core.results import CameraFit, Prior, WindowFit

__all__ = ['Alt', 'CameraStream', 'Job', 'Status']


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
    """Why the decision behind the state is not accepted ('' when it is)."""
    late_messages: int = 0
    """Messages that arrived more than ``arrival.LATE_NS`` above their stream's lag line."""
    seeds_replaced: int = 0
    """Saved offsets (``seed``) the camera's own estimate disagreed with, and replaced."""
    frozen: bool = False
    """``freeze``: corrections kept, nothing fitted."""
    prior: Prior | None = None
    """What placed the windows of the decision behind the state (``evidence``; None: the reference, or no
    decision yet)."""
    prior_reason: str = ''


@dataclass
class Alt:
    """A camera's windows placed by its events alone, fitted beside those its arrival times place while
    its decision under the arrival prior does not stand (live; ``evidence``)."""

    centre_ns: int
    """Where its windows are searched: its first events against the reference's, then its accepted line."""
    fits: dict[tuple[int, int], WindowFit] = field(default_factory=dict)
    estimate: CameraFit | None = None


@dataclass
class CameraStream:
    """What the engine holds of one camera: its bins, arrival track, lock and decisions so far."""

    topic: str
    grid_ns: int
    arrival: ArrivalTrack
    lock: CameraLock
    correction_in: ClockCorrection | None = None
    """A skew its times are binned through (the offline second pass)."""
    fixed_prior_ns: int | None = None
    """Where its windows are searched, when the feeder knows (the offline second pass)."""
    known: Known = Known()
    """What its decision knows beyond its windows."""
    model: str = ''
    """What tells camera models apart (the feeder's: type, encoding, geometry)."""
    bins: BinnedStream = field(init=False)
    first_ns: int | None = None
    """Its first event since it (re)started: the prior when no arrival time is known."""
    last_receipt: int | None = None
    estimate: CameraFit | None = None
    """The newest decision (accepted or not), of whichever placement ``evidence.choose`` took."""
    own: CameraFit | None = None
    """The newest decision of its windows placed as ``Engine.prior`` places them (live)."""
    alt: Alt | None = None
    """Live: its windows placed by its events alone, while they are needed."""
    fits: dict[tuple[int, int], WindowFit] = field(default_factory=dict)
    """Refined: the windows fitted, by (start, length), light (``WindowFit.light``)."""
    whole: WindowFit | None = None
    """Offline: the most confident window with its curve and counts (what a report draws)."""
    stretch: tuple[tuple[tuple[int, int], int], CameraFit] | None = None
    """((stretch, generation), its decision): a decision refused for quiet windows outside a stretch,
    decided again on that stretch alone (``Engine._stretched``)."""
    paper: PaperLoop = field(default_factory=PaperLoop)
    """The paper's method: its loop since the stream (re)started."""
    tried: int = 0
    accepted: int = 0
    jumps: int = 0
    events: int = 0
    far_events: int = 0
    late: int = 0
    arrivals: int = 0
    """Messages with an arrival time."""
    generation: int = 0
    since_ns: int | None = None
    """Windows begin after this: its first event after its last silence or restart."""
    resumed: bool = False
    silent: bool = False
    restart_ns: int | None = None
    """After a clock step, only windows from here on (reference timeline) make the estimate."""
    jumps_seen: list[tuple[int, int, int]] = field(default_factory=list)
    """Each clock jump its lag line saw: (arrival time, its event time then, by how much)."""

    def __post_init__(self) -> None:
        self.bins = BinnedStream(grid_ns=self.grid_ns, correction=self.correction_in)

    def forget(self, state: State, message: str) -> None:
        """Drop the estimate (a clock jumped): windows, line, correction; fits under way are stale."""
        self.fits.clear()
        self.paper = PaperLoop()
        self.restart_ns = self.estimate = self.own = self.alt = None
        self.generation += 1
        self.lock.forget(state, message)

    def reset(self, state: State, message: str) -> None:
        """Start over: the estimate, and the bins and arrival line of the old clock."""
        self.bins = BinnedStream(grid_ns=self.grid_ns, correction=self.correction_in)
        self.since_ns = self.first_ns = None
        self.arrival.restart()
        self.forget(state, message)


Job = tuple[int, CameraStream, bool, GridCounts, GridCounts, int, int, int]
"""(generation, stream, whether its events alone placed it (``Alt``), reference counts, camera counts,
window start, length, prior)."""
