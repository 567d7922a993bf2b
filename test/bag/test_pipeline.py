"""A restamp whose chunks are made in a forked process (``pipeline.pipelined``) writes what the one
process writes (``pipeline.serial``): the same files, byte for byte, and the same report, for mcap,
ROS 1 and sqlite3 bags (into sqlite3 rows and into mcap chunks) of real recordings with malformed
messages among them; a sqlite3 input is read in the child through a connection of its own. The pipeline itself: blocks
written in order, from shared memory or pickled when too big for it; the child's state given back;
an error in either process, or the child's death, ends the restamp with an error and leaves no
output; no child is left behind."""

from __future__ import annotations

import contextlib
import datetime as dt
import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from evsync_ros.bag import pipeline, restamp, storage_sqlite3
from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.errors import BagError
from evsync_testing.chunkcopies import CASES, EVT3, file_compressed, mixed_rows, write_mixed


@pytest.fixture(autouse=True)
def deadline() -> Iterator[None]:
    """A pipeline that waits forever (a slot never handed back) fails here instead of hanging the suite."""
    def expired(signum: int, frame: object) -> None:
        raise TimeoutError('the pipeline did not finish within 120 s')

    before = signal.signal(signal.SIGALRM, expired)
    signal.alarm(120)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, before)


class _Fixed(dt.datetime):
    """A clock that always says the same: two outputs' metadata then differ in nothing."""

    @classmethod
    def now(cls, tz: dt.tzinfo | None = None) -> _Fixed:
        return cls(2026, 1, 1, tzinfo=tz)


@pytest.fixture(scope='module')
def mixed(real_data: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, Path]]:
    """``chunkcopies``' mixed bag, and with late record times, as mcap, ROS 1 and sqlite3."""
    rows = mixed_rows(real_data)
    folder = tmp_path_factory.mktemp('pipeline')
    return {kind: (write_mixed(folder / f'in{kind}{suffix}', rows, storage=kind),
                   write_mixed(folder / f'late{kind}{suffix}', rows, late=True, storage=kind))
            for kind, suffix in (('mcap', ''), ('ros1', '.bag'), ('sqlite3', ''))}


def _files(bag: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(bag.iterdir())} if bag.is_dir() else {bag.name: bag.read_bytes()}


@pytest.mark.parametrize(('kind', 'storage'), [('mcap', None), ('ros1', None), ('sqlite3', None), ('sqlite3', 'mcap')])
@pytest.mark.parametrize('case', list(CASES))
def test_a_forked_restamp_writes_what_one_process_writes(mixed, tmp_path, monkeypatch, own_connections, forks, kind,
                                                         storage, case):
    monkeypatch.setattr(restamp, 'datetime', _Fixed)
    batches, read = storage_sqlite3.batches, []

    def small(storage, *args, **kwargs):  # many blocks, so that the slots are used again and again
        for batch in batches(storage, *args, **{**kwargs, 'size': 7}):
            read.append(1)
            yield batch

    monkeypatch.setattr(storage_sqlite3, 'batches', small)
    src = mixed[kind][case == 'record times moved out of range']
    kwargs = {'reference': EVT3, 'storage': storage, **CASES[case]}
    suffix = src.suffix
    (tmp_path / 'one').mkdir()
    (tmp_path / 'two').mkdir()
    one = restamp_bag(src, tmp_path / 'one' / f'out{suffix}', parallel=False, **kwargs)
    assert not forks and (kind != 'sqlite3' or len(read) > 4 * pipeline._SLOTS)
    two = restamp_bag(src, tmp_path / 'two' / f'out{suffix}', parallel=True, **kwargs)
    assert forks == [1], 'the pipeline was not taken'
    assert two.topics == one.topics and one.bad > 0
    assert _files(tmp_path / 'two' / f'out{suffix}') == _files(tmp_path / 'one' / f'out{suffix}')


def test_a_sqlite3_connection_that_crossed_a_fork_is_caught(mixed, tmp_path, monkeypatch, own_connections):
    """The check above can fail: a forked read through the parent's connection is refused."""
    monkeypatch.setattr(storage_sqlite3, 'connection', lambda part: contextlib.nullcontext(part.file.dbconn))
    with pytest.raises(RuntimeError, match='crossed a fork'):
        restamp_bag(mixed['sqlite3'][0], tmp_path / 'out', reference=EVT3, parallel=True, **CASES[next(iter(CASES))])
    assert not (tmp_path / 'out').exists()


def _blocks(sizes: list[int], state: dict[str, int]) -> Iterator[pipeline.Block]:
    """Blocks of ``sizes`` bytes (block i's bytes all i, its meta (i, an array)), counting in
    ``state`` as they are made."""
    for i, size in enumerate(sizes):
        state['made'] = state.get('made', 0) + 1

        def fill(out: bytearray | memoryview, i: int = i, size: int = size) -> tuple[int, tuple | None]:
            if len(out) < size:
                if not isinstance(out, bytearray):
                    return size, None
                out.extend(bytes(size - len(out)))
            out[:size] = bytes([i]) * size
            return size, (i, np.arange(i, i + 2, dtype=np.int64))

        yield pipeline.Block(fill)


def _collect(seen: list[tuple[int, bytes, int, list[int]]]) -> pipeline.Use:
    def use(data, meta):
        seen.append((len(data), bytes(data), meta[0], meta[1].tolist()))
    return use


def test_blocks_arrive_in_order_from_shared_memory_or_pickled_when_too_big(monkeypatch):
    monkeypatch.setattr(pipeline, 'SLOT_BYTES', 64)  # the child, a fork, has it too
    sizes = [10, 100, 30, 64, 65, 0, 7] * 3
    seen: list = []
    state: dict[str, int] = {}
    out = pipeline.pipelined(_blocks(sizes, state), _collect(seen), result=lambda: dict(state), name='in.mcap')
    assert out == {'made': len(sizes)}  # the child's state, which this process never saw
    assert state == {}
    serial: list = []
    pipeline.serial(_blocks(sizes, {}), _collect(serial))
    assert seen == serial
    assert [s[0] for s in seen] == sizes and [s[2] for s in seen] == list(range(len(sizes)))
    assert all(s[1] == bytes([i]) * n for i, (s, n) in enumerate(zip(seen, sizes)))


def _no_child_left() -> None:
    with pytest.raises(ChildProcessError):
        os.waitpid(-1, os.WNOHANG)


def test_an_error_in_the_child_is_raised_here():
    def failing() -> Iterator[pipeline.Block]:
        yield from _blocks([5, 5], {})
        raise BagError('in.mcap: chunk at byte 7 cannot be read')

    seen: list = []
    with pytest.raises(BagError, match='in.mcap: chunk at byte 7'):
        pipeline.pipelined(failing(), _collect(seen), result=dict, name='in.mcap')
    assert len(seen) == 2
    _no_child_left()


def test_an_error_that_does_not_pickle_comes_back_as_its_text():
    class Local(Exception):  # a local class cannot be pickled
        pass

    def failing() -> Iterator[pipeline.Block]:
        yield from _blocks([1], {})
        raise Local('odd')

    with pytest.raises(BagError, match='Local: odd'):
        pipeline.pipelined(failing(), _collect([]), result=dict, name='in.mcap')
    _no_child_left()


def test_the_childs_death_is_an_error():
    def dying() -> Iterator[pipeline.Block]:
        yield from _blocks([5], {})
        os.kill(os.getpid(), signal.SIGKILL)  # the child's own pid: it is killed, as the OOM killer would
        yield from _blocks([5], {})

    seen: list = []
    with pytest.raises(BagError, match='in.mcap: the process reading it ended before it finished'):
        pipeline.pipelined(dying(), _collect(seen), result=dict, name='in.mcap')
    assert len(seen) == 1
    _no_child_left()


def test_an_interrupt_while_a_slot_is_viewed_is_the_interrupt():
    """Ctrl-C inside the write, its traceback holding a view of a slot: the interrupt reaches the
    caller, not the shared memory's refusal to close."""
    def use(data, meta):
        piece = data[1:3]  # noqa: F841 - held by the traceback, as a writer's slice of the records is
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        pipeline.pipelined(_blocks([5, 5], {}), use, result=dict, name='in.mcap')
    _no_child_left()


def test_a_child_killed_in_the_middle_of_a_message_is_an_error():
    """The child's second block announces more than a pipe holds; it is killed while writing it."""
    def announced(i: int) -> pipeline.Block:
        return pipeline.Block(lambda out: (0, (i, os.getpid(), np.zeros(1 << 17, np.int64))))

    def blocks() -> Iterator[pipeline.Block]:
        for i in range(3):
            yield announced(i)

    def use(data, meta):
        if meta[0] == 0:
            time.sleep(0.5)  # the child is writing block 1 by now, the pipe full
            os.kill(meta[1], signal.SIGKILL)

    with pytest.raises(BagError, match='ended before it finished'):
        pipeline.pipelined(blocks(), use, result=dict, name='in.mcap')
    _no_child_left()


def test_no_process_to_be_had_is_the_work_done_here(monkeypatch):
    def refused() -> int:
        raise OSError(11, 'Resource temporarily unavailable')

    monkeypatch.setattr(os, 'fork', refused)
    seen: list = []
    state: dict[str, int] = {}
    made = pipeline.pipelined(_blocks([3, 4], state), _collect(seen), result=lambda: dict(state), name='in.mcap')
    assert made == {'made': 2}
    assert [s[0] for s in seen] == [3, 4]


def test_an_error_writing_kills_the_child():
    def endless() -> Iterator[pipeline.Block]:
        while True:
            yield from _blocks([5], {})

    def write(*args):
        raise OSError(28, 'No space left on device')

    with pytest.raises(OSError, match='No space'):
        pipeline.pipelined(endless(), write, result=dict, name='in.mcap')
    _no_child_left()


def test_an_interrupted_forked_restamp_leaves_no_output(mixed, tmp_path, monkeypatch, forks):
    """Ctrl-C while the child makes chunks: the error reaches restamp_bag, which removes the output."""
    real = restamp._restamp_chunk
    calls = []

    def interrupted(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(restamp, '_restamp_chunk', interrupted)
    out = tmp_path / 'out'
    with pytest.raises(KeyboardInterrupt):
        restamp_bag(mixed['mcap'][0], out, reference=EVT3, parallel=True, **CASES[next(iter(CASES))])
    assert forks == [1] and not calls  # raised in the child, whose calls this process never sees
    assert not out.exists() and not list(tmp_path.iterdir())
    _no_child_left()


def test_no_fork_while_another_thread_runs():
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert not pipeline.available()
    finally:
        stop.set()
        other.join()


def _split(real_data: Path, folder: Path, storages: tuple[str, str]) -> Path:
    """``chunkcopies``' mixed rows in two storage files of one bag, the first half in a file of
    ``storages[0]``, the second in one of ``storages[1]`` (no metadata.yaml: read file by file)."""
    rows = mixed_rows(real_data)
    bag = folder / f'split_{"_".join(storages)}'
    bag.mkdir()
    half = len(rows) // 2
    for i, (part, storage) in enumerate(zip((rows[:half], rows[half:]), storages)):
        written = write_mixed(folder / f'part{i}_{storage}', part, storage=storage)
        for f in written.iterdir():
            if f.suffix in ('.db3', '.mcap'):
                f.rename(bag / f'part_{i}{f.suffix}')
    return bag


@pytest.mark.parametrize('storages', [('sqlite3', 'sqlite3'), ('mcap', 'sqlite3'), ('sqlite3', 'mcap')])
def test_a_bag_of_several_storage_files_is_read_each_file_through_its_own(real_data, tmp_path, monkeypatch,
                                                                          own_connections, forks, storages):
    """Each storage file a chunk at a time, forked or not, as message by message: its own rows (a
    file read through another's connection gives another output), in the files' order."""
    monkeypatch.setattr(restamp, 'datetime', _Fixed)
    bag = _split(real_data, tmp_path, storages)
    kwargs = {'reference': EVT3, 'storage': 'sqlite3', **CASES[next(iter(CASES))]}
    outs = {}
    for how in ('forked', 'one process', 'messages'):
        (tmp_path / how).mkdir()
        if how == 'messages':
            monkeypatch.setattr(restamp, '_chunked', lambda *a, **k: None)
        restamp_bag(bag, tmp_path / how / 'out', parallel=how == 'forked', **kwargs)
        outs[how] = _files(tmp_path / how / 'out')
    assert forks == [1], 'the pipeline was not taken'
    assert outs['forked'] == outs['one process'] == outs['messages']


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_a_bag_compressed_file_by_file_is_restamped_forked_from_its_one_copy(
        mixed, tmp_path, monkeypatch, own_connections, forks, decompressions, storage):
    """rosbags decompresses such a bag whole as it opens it; the forked process reads that copy (a
    sqlite3 one through a connection of its own), and writes what one process writes."""
    monkeypatch.setattr(restamp, 'datetime', _Fixed)
    bag = file_compressed(mixed[storage][0], tmp_path / 'zstd', storage)
    kwargs = {'reference': EVT3, 'storage': 'sqlite3', **CASES[next(iter(CASES))]}
    for how in ('forked', 'one process'):
        (tmp_path / how).mkdir()
        restamp_bag(bag, tmp_path / how / 'out', parallel=how == 'forked', **kwargs)
    assert forks == [1] and decompressions == [1, 1]  # one copy for each restamp, none again in the forked process
    assert _files(tmp_path / 'forked' / 'out') == _files(tmp_path / 'one process' / 'out')
