"""Where the online estimator's heavy calls run: in the calling thread, or in a process of its own.

The live node's message path and its estimator share one interpreter. Fitted in a thread, the
estimator's numpy work holds the GIL between operations, and every message callback waits for it:
at the drivers' rate (a message per millisecond per camera, four cameras, 2 cores) 15 windows took
471 ms to fit there against 93 ms in a process of their own, and the messages reaching the node's
subscribers were late for as long. ``InProcess`` runs the same calls in a worker process with its
own interpreter: the node's thread only hands the counts over and takes the fits back.

The worker is ``python -m evsync_ros.runtime.worker``, started with ``subprocess`` (not
multiprocessing: its spawn runs the parent's main script again in the child, which a user's script
that builds the node without a ``__main__`` guard does not survive, and fork would copy a process
running DDS threads). Calls and results go as pickles over its stdin and stdout, one at a time.

Both runners take module-level functions and their arguments (what pickles) and return the
results in order; what a call raises is raised by ``run``.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import struct
import subprocess
import sys
from collections.abc import Callable, Sequence
from enum import Enum
from typing import IO, Any, TypeVar

from evsync_ros.core.errors import ParameterError, StreamError
from evsync_ros.core.runner import InThread, Runner

T = TypeVar('T')


class Estimator(str, Enum):
    """Where the estimator runs: the node's ``estimator`` parameter (``runner``)."""

    THREAD = 'thread'
    PROCESS = 'process'

    def __str__(self) -> str:
        return self.value

    @classmethod
    def choices(cls) -> tuple[str, ...]:
        return tuple(m.value for m in cls)


_LENGTH = struct.Struct('<Q')

WORKER = 'evsync_ros.runtime.worker'
"""The worker's module (``python -m``), which nothing imports: run as a script, it is loaded once."""


class WorkerDied(Exception):
    """The worker's pipe ended: it exited or was killed (or, in the worker, its caller closed it)."""


def send(stream: IO[bytes], obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_LENGTH.pack(len(data)))
    stream.write(data)
    stream.flush()


def receive(stream: IO[bytes]) -> Any:
    head = stream.read(_LENGTH.size)
    if len(head) < _LENGTH.size:
        raise WorkerDied
    (n,) = _LENGTH.unpack(head)
    data = stream.read(n)
    if len(data) < n:
        raise WorkerDied
    return pickle.loads(data)


class InProcess:
    """Each call in one worker process, started here (its start-up, about half a second of imports,
    is not paid by the first estimate). ``nice``: added to the worker's niceness (0: as the node).
    The worker dies with the process that started it, however that one dies (Linux prctl), and
    when its stdin closes (``close``). A worker that dies (killed, out of memory) is started again
    once per ``run``; if the new one dies too, StreamError."""

    def __init__(self, *, nice: int = 0) -> None:
        self.nice = nice
        self.restarts = 0
        """Workers started again after one died."""
        self._proc = self._start()

    @property
    def pid(self) -> int:
        """The worker's process id."""
        return self._proc.pid

    @property
    def where(self) -> str:
        return f'estimator process {self.pid}' + (f' (niceness +{self.nice})' if self.nice else '')

    def _start(self) -> subprocess.Popen[bytes]:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))  # what this process imports
        proc = subprocess.Popen([sys.executable, '-m', WORKER, str(os.getpid()), str(self.nice)],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        assert proc.stdout is not None
        try:
            ready = receive(proc.stdout)
        except WorkerDied:
            proc.wait()
            raise StreamError(f'the estimator process did not start (exit status {proc.returncode})') from None
        if ready != proc.pid:
            proc.kill()
            proc.wait()
            raise StreamError(f'the estimator process said {ready!r} at its start')
        return proc

    def run(self, fn: Callable[..., T], calls: Sequence[tuple[Any, ...]]) -> list[T]:
        if not calls:
            return []
        try:
            return self._run(fn, calls)
        except WorkerDied:
            self._end()
            self.restarts += 1
            self._proc = self._start()
            try:
                return self._run(fn, calls)
            except WorkerDied:
                self._end()
                raise StreamError(f'the estimator process (pid {self.pid}) died twice in one estimate') from None

    def _run(self, fn: Callable[..., T], calls: Sequence[tuple[Any, ...]]) -> list[T]:
        stdin, stdout = self._proc.stdin, self._proc.stdout
        assert stdin is not None and stdout is not None
        out = []
        for args in calls:  # one at a time: a pipe both sides write to at once can fill both ways
            try:
                send(stdin, (fn, args))
            except (BrokenPipeError, ValueError):  # ValueError: the pipe was closed here already
                raise WorkerDied from None
            ok, value = receive(stdout)
            if not ok:
                raise value
            out.append(value)
        return out

    def _end(self) -> None:
        for stream in (self._proc.stdin, self._proc.stdout):
            with contextlib.suppress(OSError):
                if stream is not None:
                    stream.close()
        try:
            self._proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()

    def close(self) -> None:
        """Stop the worker (its stdin closes; it exits) and wait for it."""
        self._end()


RUNNERS: dict[Estimator, Callable[[int], Runner]] = {
    Estimator.THREAD: lambda nice: InThread(),
    Estimator.PROCESS: lambda nice: InProcess(nice=nice),
}
"""Each place's runner, made with the niceness asked for (which only a process of its own takes)."""


def runner(kind: Estimator | str, *, nice: int = 0) -> Runner:
    """``thread`` (InThread) or ``process`` (InProcess); ParameterError naming the choices otherwise."""
    try:
        place = Estimator(kind)
    except ValueError:
        raise ParameterError(f'estimator must be one of {Estimator.choices()}, got {kind!r}') from None
    return RUNNERS[place](nice)
