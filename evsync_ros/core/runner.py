"""Where the engine's heavy calls run: the protocol it is handed (``Runner``) and the calling thread
(``InThread``, the default). Runners in processes of their own are process plumbing, outside the
numpy core: ``evsync_ros.runtime.runner``."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol, TypeVar

__all__ = ['InThread', 'Runner']

T = TypeVar('T')


class Runner(Protocol):
    @property
    def where(self) -> str: ...

    restarts: int
    """Workers started again after one died (0 in a thread)."""

    def run(self, fn: Callable[..., T], calls: Sequence[tuple[Any, ...]]) -> list[T]: ...

    def close(self) -> None: ...


class InThread:
    """Each call in the calling thread."""

    where = 'estimator in a thread of this process'
    restarts = 0

    def run(self, fn: Callable[..., T], calls: Sequence[tuple[Any, ...]]) -> list[T]:
        return [fn(*args) for args in calls]

    def close(self) -> None:
        pass
