"""Several bags in one ``evsync estimate`` or ``evsync restamp``: each bag in a process of its own
(``python -m evsync_ros.cli.bagjob``), at most ``--jobs`` at once, then one summary (docs/bags.md,
"A session of recordings").

A bag's process runs the one-bag command on it, so each bag gets the result it gets alone. Its
output reaches the terminal as it comes (``--jobs 1``) or line by line behind the bag's name.
The processes have a process group of their own: Ctrl-C (or SIGTERM) reaches this process only,
which sends each running bag one SIGTERM and waits for it to remove its partial output; a bag that
has not ended ``STOP_GRACE_S`` later is killed, and its partial output removed here.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import enum
import json
import os
import pickle
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from evsync_ros.bag.writer import remove_stale_partials
from evsync_ros.cli.command import Exit
from evsync_ros.errors import EvsyncError

__all__ = ['BagRun', 'Outcome', 'Plan', 'Ran', 'Relay', 'exit_status', 'many', 'outputs', 'run_bags', 'summary_json',
           'summary_table']

WORKER = 'evsync_ros.cli.bagjob'
"""The module a bag's process runs (``python -m``)."""
INTERRUPTED = int(Exit.INTERRUPTED)
"""The exit status of a command, or a bag, stopped by Ctrl-C or SIGTERM."""
CLOSED_PIPE = int(Exit.CLOSED_PIPE)
"""The exit status of a bag whose standard output's reader had gone (the command's, ``| head``)."""
STOP_GRACE_S = 10.0
"""How long a bag has to end after its SIGTERM before it is killed (it removes its partial output
within a second; one that has not ended by then would otherwise keep the command waiting)."""


@dataclass(frozen=True)
class Ran:
    """What one bag's estimate or restamp says beside its exit status: cameras accepted of those
    estimated (None when nothing was estimated), the estimate (the ``--json`` contract's object),
    the output written."""

    status: int
    accepted: int | None = None
    cameras: int | None = None
    estimate: dict[str, Any] | None = None
    output: str | None = None

    def as_json(self) -> dict[str, Any]:
        return {'status': self.status, 'accepted': self.accepted, 'cameras': self.cameras,
                'estimate': self.estimate, 'output': self.output}


class Outcome(enum.Enum):
    """A bag's result, from its exit status (the one-bag command's)."""

    DONE = 'done'
    """0: every camera accepted (and, restamping, every message restamped)."""
    INCOMPLETE = 'incomplete'
    """1: estimate, a camera not accepted (or one camera alone); restamp, messages written unchanged."""
    ERROR = 'error'
    """2: a clear error, named on standard error; nothing written."""
    INTERRUPTED = 'interrupted'
    """130: stopped by Ctrl-C or SIGTERM; its partial output removed."""
    NOT_STARTED = 'not started'
    """Interrupted before its turn."""
    CLOSED_PIPE = 'closed pipe'
    """141: its standard output (the command's) was closed by its reader; the command ends there."""
    DIED = 'died'
    """Its process ended without a result (killed, out of memory)."""

    @classmethod
    def of(cls, status: int) -> Outcome:
        return {0: cls.DONE, 1: cls.INCOMPLETE, 2: cls.ERROR, INTERRUPTED: cls.INTERRUPTED,
                CLOSED_PIPE: cls.CLOSED_PIPE}.get(status, cls.DIED)


class Relay(enum.Enum):
    """Where a bag's process writes."""

    INHERIT = 'inherit'
    """To this terminal, as the one-bag command does (one bag at a time: progress bars and all)."""
    PREFIX = 'prefix'
    """Line by line, each behind the bag's name (several at a time)."""


@dataclass(frozen=True)
class Plan:
    """One bag to run: the input, and for restamp its output."""

    bag: str
    output: str | None = None


@dataclass(frozen=True)
class BagRun:
    """One bag's run: its plan, its exit status and result, how long it took, what it said."""

    plan: Plan
    status: int
    outcome: Outcome
    seconds: float
    ran: Ran | None = None
    error: str | None = None


def many(args: argparse.Namespace, plans: Sequence[Plan], *, restamp: bool = False) -> int:
    """Each bag in its own process, ``--jobs`` at once; the summary (a table, or with ``--json`` one
    object) and the exit status of them all (``exit_status``)."""
    relay = Relay.INHERIT if args.jobs == 1 else Relay.PREFIX
    runs = run_bags(plans, args, jobs=args.jobs, relay=relay, quiet=args.json)
    if args.json:
        json.dump(summary_json(runs), sys.stdout)
        sys.stdout.write('\n')
    else:
        print(f'\n{len(runs)} bags, {args.jobs} at a time\n' + summary_table(runs, restamp=restamp))
    return exit_status(runs)


def outputs(bags: Sequence[str], *, directory: str | None, suffix: str) -> list[Plan]:
    """Each input's output: ``DIRECTORY`` (default: the input's own folder) / its name, ``suffix``
    before a ROS 1 bag's ``.bag`` (a single .db3/.mcap file gives a bag directory of its stem).
    EvsyncError, before anything runs, when an output would be an input or two inputs one output."""
    plans = [Plan(bag, str(_output(Path(bag), directory=directory, suffix=suffix))) for bag in bags]
    inputs = {Path(p.bag).resolve(): p.bag for p in plans}
    seen: dict[Path, str] = {}
    for p in plans:
        assert p.output is not None
        out = Path(p.output).resolve()
        if out in inputs:
            raise EvsyncError(f'{p.bag}: its output would be {inputs[out]}, an input; nothing written '
                              '(give --output-dir another folder, or --suffix)')
        if out in seen:
            raise EvsyncError(f'{seen[out]} and {p.bag} would both be written to {p.output}; nothing written '
                              '(bags of the same name: restamp them into different --output-dir)')
        seen[out] = p.bag
    return plans


def _output(bag: Path, *, directory: str | None, suffix: str) -> Path:
    folder = Path(directory) if directory is not None else bag.parent
    if bag.suffix == '.bag':
        return folder / f'{bag.stem}{suffix}.bag'
    if bag.suffix in ('.db3', '.mcap') and bag.is_file():
        return folder / f'{bag.stem}{suffix}'
    return folder / f'{bag.name}{suffix}'


def run_bags(plans: Sequence[Plan], args: argparse.Namespace, *, jobs: int, relay: Relay,
             quiet: bool = False) -> list[BagRun]:
    """Run ``args.one`` on each plan, each in its own process, at most ``jobs`` at once; the runs in
    the plans' order. ``quiet``: the processes' standard output is dropped (``--json``: this
    process prints). Interrupted, it stops the running bags, starts no more, and returns."""
    done: queue.Queue[tuple[int, BagRun]] = queue.Queue()
    runs: dict[int, BagRun] = {}
    pending = deque(enumerate(plans))
    running: dict[int, _Job] = {}
    closed = threading.Event()
    """Set when this process's standard output, which the bags' go to, was closed by its reader."""
    with tempfile.TemporaryDirectory(prefix='evsync-bags-') as results:
        try:
            while pending or running:
                while pending and len(running) < jobs:
                    i, plan = pending.popleft()
                    _say(f'{plan.bag}: started ({i + 1} of {len(plans)})', relay)
                    running[i] = _Job(i, plan, args, result=Path(results) / f'{i}.json', relay=relay,
                                      quiet=quiet, done=done, closed=closed)
                i, run = _next(done, closed)
                runs[i] = run
                del running[i]
                if run.outcome is Outcome.CLOSED_PIPE:
                    raise BrokenPipeError(f'{run.plan.bag}: its standard output was closed')
                _say(f'{run.plan.bag}: {_describe(run)}', relay)
        except KeyboardInterrupt:
            _stop(running, runs, done)
        except BrokenPipeError:  # the command's reader has gone: the others stopped as by Ctrl-C, unsaid
            _stop(running, runs, done, said=False)
            raise
    for i, plan in pending:
        runs[i] = BagRun(plan, INTERRUPTED, Outcome.NOT_STARTED, 0.0)
    return [runs[i] for i in range(len(plans))]


def _next(done: queue.Queue[tuple[int, BagRun]], closed: threading.Event) -> tuple[int, BagRun]:
    """The next bag to end; BrokenPipeError once standard output is ``closed``."""
    while True:
        try:
            return done.get(timeout=0.1)
        except queue.Empty:
            if closed.is_set():
                raise BrokenPipeError('standard output was closed') from None


def _stop(running: dict[int, _Job], runs: dict[int, BagRun], done: queue.Queue[tuple[int, BagRun]], *,
          said: bool = True) -> None:
    """One SIGTERM to each running bag, then wait for each to clean up (a second Ctrl-C waits too);
    those still running ``STOP_GRACE_S`` later are killed."""
    if said:
        print(f'evsync: interrupted; stopping {len(running)} running bag(s) and removing their partial outputs',
              file=sys.stderr)
    for job in running.values():
        job.terminate()
    deadline: float | None = time.monotonic() + STOP_GRACE_S
    while running:
        try:
            i, run = done.get(timeout=None if deadline is None else max(deadline - time.monotonic(), 0.01))
        except KeyboardInterrupt:
            continue
        except queue.Empty:
            for job in running.values():
                job.kill()
            deadline = None
            continue
        runs[i] = run
        running.pop(i, None)


class _Job:
    """One bag's process: started with its pickled arguments, its output relayed, its result put on
    ``done`` when it ends."""

    def __init__(self, index: int, plan: Plan, args: argparse.Namespace, *, result: Path, relay: Relay,
                 quiet: bool, done: queue.Queue[tuple[int, BagRun]], closed: threading.Event) -> None:
        self.index, self.plan, self.result, self.done = index, plan, result, done
        self.stopped = self.killed = False
        self.t0 = time.monotonic()
        one = copy.copy(args)
        one.bag, one.out = plan.bag, plan.output
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))  # what this process imports
        pipe = subprocess.PIPE if relay is Relay.PREFIX else None
        sys.stdout.flush()
        sys.stderr.flush()
        self.proc = subprocess.Popen([sys.executable, '-m', WORKER, str(result), str(os.getpid())],
                                     stdin=subprocess.PIPE, stdout=subprocess.DEVNULL if quiet else pipe,
                                     stderr=pipe, env=env, process_group=0)
        assert self.proc.stdin is not None
        with contextlib.suppress(BrokenPipeError):
            self.proc.stdin.write(pickle.dumps(one, protocol=pickle.HIGHEST_PROTOCOL))
        with contextlib.suppress(BrokenPipeError):
            self.proc.stdin.close()
        relays = [threading.Thread(target=_relay, args=(stream, f'{plan.bag}: ', out, closed), daemon=True)
                  for stream, out in ((self.proc.stdout, sys.stdout), (self.proc.stderr, sys.stderr))
                  if stream is not None]
        for t in relays:
            t.start()
        threading.Thread(target=self._wait, args=(relays,), daemon=True).start()

    def terminate(self) -> None:
        self.stopped = True
        with contextlib.suppress(ProcessLookupError):
            self.proc.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        """End a bag that did not answer its SIGTERM; its partial output is removed once it is gone."""
        print(f'evsync: {self.plan.bag} did not stop within {STOP_GRACE_S:g} s of its SIGTERM; killing it',
              file=sys.stderr)
        self.killed = True
        with contextlib.suppress(ProcessLookupError):
            self.proc.kill()

    def _wait(self, relays: list[threading.Thread]) -> None:
        status = self.proc.wait()
        for t in relays:  # (a bag killed may have left its pipes with a process of its own)
            t.join(timeout=STOP_GRACE_S if self.killed else None)
        seconds = time.monotonic() - self.t0
        try:
            doc = json.loads(self.result.read_text())
        except (OSError, ValueError):
            if self.killed and self.plan.output is not None:  # it could not remove its own
                remove_stale_partials(Path(self.plan.output))
            if self.stopped and status in (-signal.SIGTERM, -signal.SIGINT, -signal.SIGKILL):
                # killed before it could take its SIGTERM, or for not answering it
                self.done.put((self.index, BagRun(self.plan, INTERRUPTED, Outcome.INTERRUPTED, seconds)))
                return
            why = f'its process ended with {_status_words(status)} and no result'
            self.done.put((self.index, BagRun(self.plan, 2, Outcome.DIED, seconds, error=why)))
            return
        ran = Ran(**doc['ran'])
        run = BagRun(self.plan, ran.status, Outcome.of(ran.status), seconds, ran=ran, error=doc.get('error'))
        self.done.put((self.index, run))


_LOCK = threading.Lock()


def _relay(stream: IO[bytes], prefix: str, out: IO[str], closed: threading.Event) -> None:
    """Each line of ``stream`` onto ``out`` behind ``prefix`` (a progress bar's redraws as their last);
    once ``out`` is found closed by its reader, ``closed`` is set and the rest read and dropped."""
    for raw in stream:
        if closed.is_set():
            continue
        line = raw.decode(errors='replace').rstrip('\n').rsplit('\r', 1)[-1]
        try:
            with _LOCK:
                out.write(f'{prefix}{line}\n')
                out.flush()
        except BrokenPipeError:
            closed.set()
    stream.close()


def _say(line: str, relay: Relay) -> None:
    with _LOCK:
        if relay is Relay.INHERIT:
            print(f'\n== {line}', file=sys.stderr, flush=True)
        else:
            print(line, file=sys.stderr, flush=True)


def _status_words(status: int) -> str:
    return f'signal {-status}' if status < 0 else f'exit status {status}'


def _describe(run: BagRun) -> str:
    why = f': {run.error}' if run.error and run.outcome is Outcome.DIED else ''
    return f'{run.outcome.value} (exit {run.status}) in {run.seconds:.1f} s{why}'


def exit_status(runs: Sequence[BagRun]) -> int:
    """The command's: 130 when interrupted (a bag interrupted or not started), else the worst bag's:
    2 when a bag failed (an error, or its process died), else 1 when a bag's was 1, else 0."""
    if any(r.outcome in (Outcome.INTERRUPTED, Outcome.NOT_STARTED) for r in runs):
        return INTERRUPTED
    return max((min(r.status, 2) if r.status >= 0 else 2 for r in runs), default=0)


def _cameras(run: BagRun) -> str:
    ran = run.ran
    if ran is None or ran.cameras is None:
        return '-'
    return f'{ran.accepted}/{ran.cameras}'


def summary_table(runs: Sequence[BagRun], *, restamp: bool) -> str:
    """One line per bag: bag, result, exit status, cameras accepted, seconds (and the output)."""
    width = max([len('bag'), *(len(r.plan.bag) for r in runs)])
    head = f'{"bag":<{width}} {"result":<12} {"exit":>4} {"accepted":>8} {"time s":>8}'
    head += '  output' if restamp else ''
    lines = [head, '-' * len(head)]
    for r in runs:
        out = f'  {r.plan.output}' if restamp and r.outcome in (Outcome.DONE, Outcome.INCOMPLETE) else ''
        lines.append(f'{r.plan.bag:<{width}} {r.outcome.value:<12} {r.status:>4} {_cameras(r):>8} '
                     f'{r.seconds:>8.1f}{out}')
    failed = [r for r in runs if r.error]
    if failed:
        lines.append('')
        lines += [r.error if r.error.startswith(r.plan.bag) else f'{r.plan.bag}: {r.error}' for r in failed if r.error]
    return '\n'.join(lines)


def summary_json(runs: Sequence[BagRun]) -> dict[str, Any]:
    """The many-bag ``--json`` object: ``{"bags": [...]}``, one entry per bag in the order given."""
    return {'bags': [_bag_json(r) for r in runs]}


def _bag_json(run: BagRun) -> dict[str, Any]:
    ran = run.ran or Ran(status=run.status)
    written = run.outcome in (Outcome.DONE, Outcome.INCOMPLETE)
    return {'bag': run.plan.bag, 'result': run.outcome.value, 'exit': run.status, 'seconds': round(run.seconds, 3),
            'cameras_accepted': ran.accepted, 'cameras': ran.cameras, 'estimate': ran.estimate,
            'output': run.plan.output if written else None, 'error': run.error}
