"""What the engine keeps of each camera, and what it reports of one. numpy only."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

from evsync_ros.core.bins import BinnedStream, GridCounts
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine.arrival import ArrivalTrack
from evsync_ros.core.engine.lock import CameraLock, State
from evsync_ros.core.results import CameraFit, Prior
from evsync_ros.core.triggers import EdgeBuffer

__all__ = ['CameraStream', 'Job', 'Known', 'Status']


@dataclass(frozen=True)
class Known:
    """What a camera's decision knows beyond its windows."""

    systematic_ns: float = 0.0
    """Its own systematic error (cameras of another model than the reference's)."""
    skew_ppm: float = 0.0
    """The skew its times were binned through, about ``anchor_ns`` (an offline second pass)."""
    anchor_ns: int = 0
    skew_se_ppm: float = float('inf')


class Job(NamedTuple):
    """One window to fit: what the runner is handed with the parameters (a tuple: it pickles)."""

    generation: int
    """The stream's generation when planned (a fit of an older one is stale)."""
    topic: str
    alt: bool
    """Placed by the camera's events alone (``evidence``), beside its own windows."""
    ref: GridCounts
    cam: GridCounts
    start_ns: int
    """The window's start, reference timeline."""
    length_ns: int
    prior_ns: int
    """The offset its search is centred on."""
    number: int = 0
    """The paper's window number."""


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
    edges: int = 0
    """Trigger edges the correction's line was taken from (0: the density's own)."""
    density_offset_ns: int | None = None
    """With ``edges``: the density decision's offset, what the edges moved it from."""
    tied_to: str = ''
    """With ``edges``: the camera whose edges they were tied to, where not the reference."""


@dataclass
class CameraStream:
    """What the engine holds of one camera: its bins, arrival track, lock and decision; the windows are
    its method's (``methods``)."""

    topic: str
    grid_ns: int
    arrival: ArrivalTrack
    lock: CameraLock
    correction_in: ClockCorrection | None = None
    """A skew its times are binned through (the offline driver's later read)."""
    fixed_prior_ns: int | None = None
    """Where its windows are searched, when the feeder knows (the offline driver's later read)."""
    known: Known = Known()
    model: str = ''
    """What tells camera models apart (the feeder's: type, encoding, geometry)."""
    bins: BinnedStream = field(init=False)
    first_ns: int | None = None
    """Its first event since it (re)started: the prior when no arrival time is known."""
    since_ns: int | None = None
    """Windows begin after this: its first event after its last silence or restart."""
    restart_ns: int | None = None
    """After a clock step, only windows from here on (reference timeline) make the decision."""
    arrival_step_ns: int | None = None
    """Live: where (its timeline) the last clock step its arrival times showed was followed."""
    last_receipt: int | None = None
    resumed: bool = False
    silent: bool = False
    estimate: CameraFit | None = None
    """The newest decision (accepted or not), of whichever placement ``evidence.choose`` took."""
    decided: CameraFit | None = None
    """That decision as the density made it, before trigger edges tied it (``triggers.tie``)."""
    tried: int = 0
    accepted: int = 0
    jumps: int = 0
    events: int = 0
    far_events: int = 0
    late: int = 0
    arrivals: int = 0
    """Messages with an arrival time."""
    generation: int = 0
    jumps_seen: list[tuple[int, int, int]] = field(default_factory=list)
    """Each clock jump its lag line saw: (arrival time, its event time then, by how much)."""
    edges: EdgeBuffer = field(default_factory=EdgeBuffer)
    """Its trigger edges on the shared pulse's channel, where the feeder gives them (live)."""

    def __post_init__(self) -> None:
        self.bins = BinnedStream(grid_ns=self.grid_ns, correction=self.correction_in)

    def forget(self, state: State, message: str) -> None:
        """Drop the decision and correction (a clock jumped); fits under way are stale. The method
        forgets its windows (``Engine.forget``)."""
        self.restart_ns = self.estimate = self.decided = None
        self.generation += 1
        self.lock.forget(state, message)

    def reset(self, state: State, message: str) -> None:
        """Start over: the decision, and the bins and arrival line of the old clock."""
        self.bins = BinnedStream(grid_ns=self.grid_ns, correction=self.correction_in)
        self.since_ns = self.first_ns = None
        self.arrival.restart()
        self.forget(state, message)
