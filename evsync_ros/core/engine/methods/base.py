"""What every method gives the engine (``WindowMethod``), and a decision it hands a driver. numpy only."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine.params import EngineParams
from evsync_ros.core.engine.stream import CameraStream, Job
from evsync_ros.core.results import CameraFit

if TYPE_CHECKING:
    from evsync_ros.core.engine.engine import Engine

__all__ = ['Decision', 'WindowMethod']


@dataclass(frozen=True)
class Decision:
    """A camera's newest decision, as its method found it, for a driver to apply."""

    stream: CameraStream
    generation: int
    """The stream's generation when it was asked (an older one's decision is stale)."""
    correction: ClockCorrection | None
    """The correction in force when it was asked (live: one changed meanwhile makes it stale)."""
    own: CameraFit
    """From the windows placed as ``Engine.centre`` places them."""
    alt: CameraFit | None = None
    """From the windows its events alone placed, where there are (``evidence``)."""


class WindowMethod(Protocol):
    """A method as the engine runs it: where its windows go, one window's fit (a module-level function
    the runner is handed), what a fit adds, and each camera's decision."""

    @property
    def fit(self) -> Callable[[EngineParams, Job, bool], object]:
        """One window's fit: a module-level function (the runner pickles it by name)."""

    def forget(self, topic: str) -> None: ...

    def jobs(self, e: Engine, s: CameraStream) -> list[Job]: ...

    def params(self, e: Engine, job: Job) -> EngineParams: ...

    def take(self, e: Engine, s: CameraStream, job: Job, found: object) -> None: ...

    def at_end(self, e: Engine, s: CameraStream) -> list[Job]: ...

    def decide(self, e: Engine, streams: Iterable[CameraStream]) -> list[Decision]: ...

    def floors(self, e: Engine) -> dict[str, int]: ...

    def done(self, e: Engine) -> bool: ...

    def ended(self, topic: str) -> bool: ...

    def note(self, s: CameraStream, own: CameraFit, alt: CameraFit | None) -> None: ...

    def finished(self, s: CameraStream, fit: CameraFit) -> CameraFit: ...

    def restart(self, topic: str, at_ns: int) -> None: ...
