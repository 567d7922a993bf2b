"""Where the online estimator's heavy calls run: in the calling thread, or in a process of its own.

The live node's message path and its estimator share one interpreter. Fitted in a thread, the
estimator's numpy work holds the GIL between operations, and every message callback waits for it:
at the drivers' rate (a message per millisecond per camera, four cameras) the callbacks fell
behind for as long as each estimate took, and messages reached their subscribers up to 140 ms late
(``bench/node.py``). ``InProcess`` runs the same calls in a spawned process with its own
interpreter: the node's thread only hands the counts over and takes the fits back.

Both runners take module-level functions and their arguments (what pickles) and return the
results in order; what a call raises is raised by ``run``.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import ctypes
import multiprocessing
import os
import signal
from collections.abc import Callable, Sequence
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Protocol, TypeVar

from evsync_ros.core.errors import ParameterError, StreamError

T = TypeVar('T')

RUNNERS = ('thread', 'process')
"""The values of the node's ``estimator`` parameter."""


class Runner(Protocol):
    @property
    def where(self) -> str: ...

    def run(self, fn: Callable[..., T], calls: Sequence[tuple[Any, ...]]) -> list[T]: ...

    def close(self) -> None: ...


class InThread:
    """Each call in the calling thread."""

    where = 'estimator in a thread of this process'

    def run(self, fn: Callable[..., T], calls: Sequence[tuple[Any, ...]]) -> list[T]:
        return [fn(*args) for args in calls]

    def close(self) -> None:
        pass


def _ready(nice: int, parent: int) -> int:
    """The worker's first call: it dies with the process that started it, however that one dies
    (Linux prctl; else the pool's own pipes end it), and takes its priority; its pid back (the
    spawn and imports are done)."""
    with contextlib.suppress(Exception):
        ctypes.CDLL('libc.so.6', use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    if os.getppid() != parent:  # gone before the line above
        os.kill(os.getpid(), signal.SIGKILL)
    if nice:
        os.nice(nice)
    return os.getpid()


class InProcess:
    """Each call in one spawned worker process (started here, so that its start-up, about half a
    second of imports, is not paid by the first estimate). ``nice``: added to the worker's
    niceness (0: as the node). A worker that dies (killed, out of memory) is started again once per
    ``run``; if the new one dies too, StreamError."""

    def __init__(self, *, nice: int = 0) -> None:
        self.nice = nice
        self.pid = 0
        """The worker's process id."""
        self.restarts = 0
        """Workers started again after one died."""
        self._pool = self._start()

    @property
    def where(self) -> str:
        return f'estimator process {self.pid}' + (f' (niceness +{self.nice})' if self.nice else '')

    def _start(self) -> concurrent.futures.ProcessPoolExecutor:
        # spawn, not fork: the node's process runs DDS threads, which a forked child must not inherit
        pool = concurrent.futures.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context('spawn'))
        self.pid = pool.submit(_ready, self.nice, os.getpid()).result()
        return pool

    def run(self, fn: Callable[..., T], calls: Sequence[tuple[Any, ...]]) -> list[T]:
        if not calls:
            return []
        try:
            return self._run(fn, calls)
        except BrokenProcessPool:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self.restarts += 1
            self._pool = self._start()
            try:
                return self._run(fn, calls)
            except BrokenProcessPool as exc:
                raise StreamError(f'the estimator process (pid {self.pid}) died twice in one estimate') from exc

    def _run(self, fn: Callable[..., T], calls: Sequence[tuple[Any, ...]]) -> list[T]:
        futures = [self._pool.submit(fn, *args) for args in calls]
        return [f.result() for f in futures]

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)


def runner(kind: str, *, nice: int = 0) -> Runner:
    """``thread`` (InThread) or ``process`` (InProcess)."""
    if kind == 'thread':
        return InThread()
    if kind == 'process':
        return InProcess(nice=nice)
    raise ParameterError(f'estimator must be one of {RUNNERS}, got {kind!r}')
