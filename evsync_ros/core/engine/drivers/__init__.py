"""How the engine is run: live (``Live``: deciding as messages arrive, a lock per camera) or over a
recording read whole (``Offline``: deciding at its end), behind one protocol (``Driver``)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, Protocol

from evsync_ros.core.engine.drivers.live import Live
from evsync_ros.core.engine.drivers.offline import Offline
from evsync_ros.core.engine.stream import CameraStream, Job

if TYPE_CHECKING:
    from evsync_ros.core.engine.engine import Engine

__all__ = ['Driver', 'Live', 'Offline']


class Driver(Protocol):
    """What differs between running live and over a recording read whole: never the decision."""

    keeps_curves: bool
    places_alongside: bool

    def keep_ns(self, e: Engine) -> int: ...

    def tick(self, e: Engine, now_ns: int | None) -> None: ...

    def jobs(self, e: Engine, s: CameraStream) -> list[Job]: ...

    def after_step(self, e: Engine, fitted: Iterable[CameraStream]) -> None: ...
