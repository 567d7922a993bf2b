"""The estimate read and decoded in a second process (``events.read_ahead``, ``BagReader.deliver``)
finds what reading in one process finds: the same rig, reports and host envelope, through a second
pass for drifting cameras and onto host time. The batches carry every message's times, record time and order, the
cameras' models, the messages read and the envelope's adds, whatever a message's size, and each
message's least and greatest time, which the engine would otherwise find message by message."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from evsync_ros.bag import events, pipeline
from evsync_ros.bag.estimate import estimate_bag
from evsync_ros.bag.reader import BagReader
from evsync_ros.sim.pixelsim import preset, simulate
from evsync_ros.sim.simbag import write_rig
from evsync_testing.chunkcopies import file_compressed


@pytest.fixture(scope='module')
def drifting(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Cameras drifting against each other and the host, as mcap and sqlite3: the refined estimate
    reads twice."""
    rig = preset('drift', seed=2, duration_s=30)
    events = simulate(rig)
    folder = tmp_path_factory.mktemp('readahead')
    for storage in ('mcap', 'sqlite3'):
        write_rig(rig, events, folder / storage, storage=storage)
    return {storage: folder / storage for storage in ('mcap', 'sqlite3')}


def _everything(found: object) -> dict:
    return {f.name: repr(getattr(found, f.name)) for f in dataclasses.fields(found)}  # type: ignore[arg-type]


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
@pytest.mark.parametrize('reference', ['/cam0/events', 'host'])
def test_the_estimate_read_in_a_second_process_finds_what_one_process_finds(drifting, own_connections, forks,
                                                                            reference, storage):
    bag = drifting[storage]  # a sqlite3 bag read in the child through a connection of its own
    alone = estimate_bag(bag, reference=reference, parallel=False)
    assert not forks
    ahead = estimate_bag(bag, reference=reference, parallel=True)
    assert alone.passes == 2 and forks == [1, 1]  # the second read of the drifting cameras forks too
    assert _everything(ahead) == _everything(alone)
    assert ahead.rig.as_json() == alone.rig.as_json() and all(c.accepted for c in alone.rig.cameras)


@pytest.fixture
def not_opened_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """A bag opened again in a forked process (``BagReader.reopened``) fails the read, and so the test."""
    again = BagReader.reopened

    def reopened(self: BagReader) -> object:
        if os.getpid() != self._pid:
            raise RuntimeError(f'{self.path} opened again in the reading process')
        return again(self)

    monkeypatch.setattr(BagReader, 'reopened', reopened)


def test_a_sqlite3_bag_is_not_opened_again_by_the_reading_process(drifting, not_opened_again, forks):
    """The forked reader reads each sqlite3 file through a connection of its own to that file
    (``storage_sqlite3.connection``), never the whole bag opened again (rosbags' opening counts every row,
    0.16 s a GB, which the engine's process waits for)."""
    ahead = estimate_bag(drifting['sqlite3'], parallel=True)
    assert forks == [1, 1]
    assert _everything(ahead) == _everything(estimate_bag(drifting['sqlite3'], parallel=False))


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_a_bag_compressed_file_by_file_is_decompressed_once(drifting, tmp_path, forks, decompressions,
                                                            own_connections, not_opened_again, storage):
    """rosbags decompresses such a bag whole as it opens it: a forked process reads an mcap copy as
    it is, and a sqlite3 one through a connection of its own to the copy, never opening the bag
    again (which would decompress it again, and leave the copy behind if killed)."""
    bag = file_compressed(drifting['sqlite3'], tmp_path / 'zstd', storage)
    ahead = estimate_bag(bag, parallel=True)
    assert forks == [1, 1] and decompressions == [1]  # two passes, both forked, one copy
    assert ahead.rig.as_json() == estimate_bag(drifting['sqlite3'], parallel=False).rig.as_json()


def _messages(sizes: list[int]) -> list[events.Message]:
    """Messages of ``sizes`` events, every other one's times out of order (least and greatest inside)."""
    rng = np.random.default_rng(3)
    return [(f'/cam{i % 3}', (rng.permutation(n) if i % 2 else np.arange(n)).astype(np.int64) + 1000 * i, 10 * i)
            for i, n in enumerate(sizes)]


def _through(messages: list[events.Message], *, forked: bool, read_each: int = 2
             ) -> tuple[list[tuple[str, list[int], int, int | None, int | None]], list[dict[str, str]], int,
                        list[tuple[str, int, int]]]:
    """What ``unpack`` gives of ``batches`` of ``messages`` (each read with ``read_each - 1``
    undecodable ones before it, each adding to the envelope, its topic's model known from it on)."""
    read = [0]
    recorder = events.Recorder()
    models: dict[str, str] = {}

    def source() -> Iterator[events.Message]:
        for topic, t, record_ns in messages:
            read[0] += read_each
            models.setdefault(topic, f'model of {topic}')
            recorder.add(topic, int(t[0]) if t.size else 0, record_ns)
            yield topic, t, record_ns

    out: list[tuple[str, list[int], int, int | None, int | None]] = []
    seen_models: list[dict[str, str]] = []
    counts = [0]
    calls: list[tuple[str, int, int]] = []

    def use(data: memoryview | bytes, meta: tuple) -> None:
        batch, known, n_read, adds = events.unpack(data, meta)
        out.extend((topic, t.tolist(), record_ns, lo if t.size else None, hi if t.size else None)
                   for topic, t, record_ns, lo, hi in batch)
        seen_models.append(known)
        counts[0] += n_read
        calls.extend(adds)

    blocks = events.batches(source(), models=lambda: dict(models), read=read, recorder=recorder)
    if forked:
        pipeline.pipelined(blocks, use, result=lambda: None, name='in.mcap')
    else:
        pipeline.serial(blocks, use)
    return out, seen_models, counts[0], calls


def test_batches_carry_every_message_in_order_whatever_its_size(monkeypatch):
    monkeypatch.setattr(pipeline, 'SLOT_BYTES', 800)  # 100 times a slot: the child, a fork, has it too
    monkeypatch.setattr(events, 'BATCH_MESSAGES', 5)
    sizes = [3, 0, 40, 99, 100, 101, 7, 0, 0, 250, 1, 60, 60, 60] * 2
    messages = _messages(sizes)
    for forked in (False, True):
        out, models, read, calls = _through(messages, forked=forked)
        assert out == [(topic, t.tolist(), record_ns, *((int(t.min()), int(t.max())) if t.size else (None, None)))
                       for topic, t, record_ns in messages]
        assert read == 2 * len(messages)
        assert calls == [(topic, int(t[0]) if t.size else 0, record_ns) for topic, t, record_ns in messages]
        assert models[-1] == {f'/cam{i}': f'model of /cam{i}' for i in range(3)}
        assert len(models) >= len(sizes) // 5  # batches cut by count and by size


def test_what_is_read_after_the_last_message_still_counts(monkeypatch):
    read = [0]

    def source() -> Iterator[events.Message]:
        read[0] += 1
        yield '/cam0', np.arange(3, dtype=np.int64), 5
        read[0] += 4  # undecodable messages at the end: read, never yielded

    got: list[int] = []
    blocks = events.batches(source(), models=dict, read=read, recorder=None)
    pipeline.serial(blocks, lambda data, meta: got.append(events.unpack(data, meta)[2]))
    assert sum(got) == 5
