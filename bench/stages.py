"""Where the time of one ``evsync`` command goes, per stage, with explicit timers.

    ./dev run python bench/stages.py --out stages.json -- restamp BAG OUT --offsets offsets.json

Runs ``evsync`` (``evsync_ros.cli.main.main``) in this process with a timer wrapped around each
function that owns a stage, and writes ``{stage: seconds, '_main': seconds}`` as JSON to ``--out``
(the command's own output goes where it always goes). The timers are exclusive: a stage entered
while another runs is charged to the inner one only, and whatever runs outside every stage (the
command's own loop, argument parsing, metadata) is ``other``. So the stages add up to the time
``main`` took, and nothing is counted twice. Each wrapped call costs two clock reads and a Python
call (about a microsecond), paid by every message in each stage it enters: ``bench/restamp.py
--profile`` prints the same command's wall time without the timers beside it. A restamp runs in
this one process (``pipeline.available`` is made False), so that every stage is counted: the
stages are its work, which the pipeline spreads over two processes.

The stages, and what owns each:

* storage read: ``BagReader.messages`` (through its storage plugins: mcap chunks, sqlite3 rows, ROS 1
  chunks, or rosbags' readers), and the storages' chunks and rows: ``storage_mcap.chunks``,
  ``storage_ros1.chunks``, ``storage_sqlite3.batches`` and ``storage_sqlite3.messages``;
* ROS 1 conversion: ``bag.ros1.to_cdr``, ``bag.ros1.to_ros1`` (a ROS 1 bag's messages);
* decode: the adapters' decoders (``decode``, ``decode_times``, ``decode_ros1_times`` of
  ``EventPacketDecoder`` and ``EventArrayDecoder``);
* binning: ``Engine.add`` (a message's events into the bins) and ``BinnedStream.flush`` (the chunks
  a stream holds counted together, when the fitting reads them or frees bins);
* fitting: ``Engine.step``, ``Engine.finish`` (windows fitted, cameras decided, bins freed);
* restamp: the restampers (``Restamper.restamp``, ``Restamper.restamp_ros1`` of a ROS 1 bag into a
  ROS 1 bag, ``Restamper.restamp_rows`` of a chunk's rows, a companion's ``_HeaderRestamper.restamp``)
  and the chunk path's record times (``restamp._record_times``);
* storage write: ``BagWriter`` (opening, ``write``, ``write_ros1``, ``write_chunk``, ``write_rows``,
  and closing: the last commit, the mcap index, the rename into place) and the chunk path's records
  built for it (``records.build``, ``records.blobs``).
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from collections.abc import Callable, Generator, Iterator
from pathlib import Path
from typing import Any

STAGES = ('storage read', 'ROS 1 conversion', 'decode', 'binning', 'fitting', 'restamp', 'storage write', 'other')


class StageClock:
    """Exclusive time per stage: ``enter`` charges the time since the last change to the stage that
    ran until now, ``leave`` to the stage that ends."""

    def __init__(self) -> None:
        self.spent = dict.fromkeys(STAGES, 0)
        self._stack = ['other']
        self._mark = time.perf_counter_ns()

    def enter(self, stage: str) -> None:
        now = time.perf_counter_ns()
        self.spent[self._stack[-1]] += now - self._mark
        self._stack.append(stage)
        self._mark = now

    def leave(self) -> None:
        now = time.perf_counter_ns()
        self.spent[self._stack.pop()] += now - self._mark
        self._mark = now

    def reset(self) -> None:
        """Nothing charged yet, from now."""
        self.spent = dict.fromkeys(STAGES, 0)
        self._mark = time.perf_counter_ns()

    def seconds(self) -> dict[str, float]:
        """Every stage's time so far (the running one's included), in seconds."""
        self.enter('other')
        self.leave()
        return {s: ns / 1e9 for s, ns in self.spent.items()}

    def call(self, stage: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        """``fn`` with its calls charged to ``stage``."""
        @functools.wraps(fn)
        def timed(*args: Any, **kwargs: Any) -> Any:
            self.enter(stage)
            try:
                return fn(*args, **kwargs)
            finally:
                self.leave()
        return timed

    def generator(self, stage: str, fn: Callable[..., Iterator[Any]]) -> Callable[..., Iterator[Any]]:
        """A generator function ``fn`` with the making of each of its items charged to ``stage``."""
        @functools.wraps(fn)
        def timed(*args: Any, **kwargs: Any) -> Iterator[Any]:
            inner = fn(*args, **kwargs)
            try:
                while True:
                    self.enter(stage)
                    try:
                        item = next(inner)
                    except StopIteration:
                        return
                    finally:
                        self.leave()
                    yield item
            finally:
                if isinstance(inner, Generator):
                    inner.close()
        return timed


def install(clock: StageClock) -> None:
    """Wrap each stage's owners (module docstring) with ``clock``'s timers."""
    from evsync_ros.bag import pipeline, records, restamp, ros1, storage_mcap, storage_ros1, storage_sqlite3
    from evsync_ros.bag.reader import BagReader
    from evsync_ros.bag.writer import BagWriter
    from evsync_ros.core.bins import BinnedStream
    from evsync_ros.core.engine.engine import Engine
    from msg_adapters.event_array import EventArrayDecoder
    from msg_adapters.event_packet import EventPacketDecoder
    from msg_adapters.registry import Restamper

    patches: list[tuple[Any, str, str]] = [
        (ros1, 'to_cdr', 'ROS 1 conversion'), (ros1, 'to_ros1', 'ROS 1 conversion'),
        (EventPacketDecoder, 'decode', 'decode'), (EventArrayDecoder, 'decode', 'decode'),
        (EventPacketDecoder, 'decode_times', 'decode'), (EventArrayDecoder, 'decode_times', 'decode'),
        (EventPacketDecoder, 'decode_ros1_times', 'decode'),
        (Engine, 'add', 'binning'), (BinnedStream, 'flush', 'binning'),
        (Engine, 'step', 'fitting'), (Engine, 'finish', 'fitting'),
        (Restamper, 'restamp', 'restamp'), (Restamper, 'restamp_ros1', 'restamp'),
        (Restamper, 'restamp_rows', 'restamp'), (restamp, '_record_times', 'restamp'),
        (restamp._HeaderRestamper, 'restamp', 'restamp'),
        (BagWriter, '__enter__', 'storage write'), (BagWriter, 'write', 'storage write'),
        (BagWriter, 'write_ros1', 'storage write'), (BagWriter, '__exit__', 'storage write'),
        (records, 'build', 'storage write'), (records, 'blobs', 'storage write'),
        (BagWriter, 'write_chunk', 'storage write'), (BagWriter, 'write_rows', 'storage write'),
    ]
    for owner, name, stage in patches:
        setattr(owner, name, clock.call(stage, getattr(owner, name)))
    BagReader.messages = clock.generator('storage read', BagReader.messages)  # type: ignore[method-assign]
    for module, name in ((storage_mcap, 'chunks'), (storage_ros1, 'chunks'), (storage_sqlite3, 'batches'),
                         (storage_sqlite3, 'messages')):
        setattr(module, name, clock.generator('storage read', getattr(module, name)))
    # the timers run in this process: a restamp's chunks made in a forked one would go uncounted
    pipeline.available = lambda *, jobs=1: False


def run(argv: list[str]) -> tuple[int, float, dict[str, float]]:
    """(exit status, seconds, per-stage seconds) of ``evsync ARGV`` run here with the timers."""
    from evsync_ros.cli.main import main

    clock = StageClock()
    install(clock)
    t0 = time.perf_counter()
    clock.reset()  # the imports before are not the command's
    code = main(argv)
    stages = clock.seconds()
    return code, time.perf_counter() - t0, stages


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--out', required=True, help='where to write the stages (JSON)')
    parser.add_argument('argv', nargs=argparse.REMAINDER, help='the evsync command and its arguments, after --')
    args = parser.parse_args()
    argv = args.argv[1:] if args.argv[:1] == ['--'] else args.argv
    code, seconds, stages = run(argv)
    Path(args.out).write_text(json.dumps({**stages, '_main': seconds}))
    sys.exit(code)


if __name__ == '__main__':
    main()
