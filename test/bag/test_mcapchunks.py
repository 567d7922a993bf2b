"""An mcap bag restamped into mcap a chunk at a time (``restamp._copy_chunks``, ``mcapchunks``) gives
what restamping it message by message gives: the same messages, bytes, record times and order, the
same report (counts, bad messages and the first error) and the same metadata, on real recordings
with malformed messages among them, under an offset, a skew that rewrites evt3 time words, record
times kept or moved, and record times moved out of range. The chunks it writes are byte for byte
those rosbags' own writer makes of the same messages; a bag whose chunks overlap in time is copied
message by message."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from ruamel.yaml import YAML

from evsync_ros.bag import mcapchunks, restamp
from evsync_ros.bag.mcapchunks import NO_STAMP
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.bag.writer import BagWriter, _McapRecords
from evsync_ros.core.clock import ClockCorrection
from evsync_testing.digest import bag_digest
from msg_adapters.definitions import DVS_EVENT_ARRAY, EVENT_PACKET

EVT3, ARRAYS, OTHER = '/cam0/events', '/cam1/events', '/cam1/status'


def _messages(bag: Path, topic: str) -> list[tuple[int, bytes]]:
    with BagReader(bag) as reader:
        return [(t, bytes(raw)) for _, t, raw in reader.messages([topic])]


@pytest.fixture(scope='module')
def mixed(real_data, tmp_path_factory) -> tuple[Path, Path]:
    """An mcap bag of a real evt3 recording's packets and a real DVS128's EventArrays (moved into the
    same seconds, some at the very record times of packets), a topic that is no camera's, and
    malformed messages among them: truncated packets, a packet of an unknown encoding, a cut
    EventArray."""
    evt3 = _messages(real_data / 'evt3_sqlite3', '/event_camera/events')
    arrays = _messages(real_data / 'dvs128_stereo/fan', '/left/events')[:400]
    t0 = evt3[0][0]
    moved = [(t0 + (t - arrays[0][0]) % (evt3[-1][0] - t0), raw) for t, raw in arrays]
    moved[::7] = [(evt3[i * 3][0], raw) for i, (_, raw) in enumerate(moved[::7])]  # ties across topics
    evt3 = [(t, raw[: len(raw) // 2] if i % 50 == 7 else raw) for i, (t, raw) in enumerate(evt3)]
    t, raw = evt3[11]
    evt3[11] = (t, raw.replace(b'evt3', b'evt9', 1))
    moved[5] = (moved[5][0], moved[5][1][:-40])
    rows = sorted([(t, EVT3, raw) for t, raw in evt3] + [(t, ARRAYS, raw) for t, raw in moved]
                  + [(t + 1, OTHER, b'\x00\x01\x00\x00status') for t, _ in evt3[::25]], key=lambda r: r[0])
    folder = tmp_path_factory.mktemp('mixed')
    # and the same with record times (not the recorder's clock) ending half a second short of the end
    # of int64, so that moving them by a second takes the last ones out of the bag's range
    late = (1 << 63) - 1 - 500_000_000 - (rows[-1][0] - rows[0][0])
    return _write(folder / 'in', rows), _write(folder / 'late', [(t - rows[0][0] + late, topic, raw)
                                                                  for t, topic, raw in rows])


def _write(bag: Path, rows: list[tuple[int, str, bytes]]) -> Path:
    with BagWriter(bag, storage='mcap') as writer:
        conns = {EVT3: writer.add_topic(EVT3, EVENT_PACKET), ARRAYS: writer.add_topic(ARRAYS, DVS_EVENT_ARRAY),
                 OTHER: writer.add_topic(OTHER, 'std_msgs/msg/String')}
        for t, topic, raw in rows:
            writer.write(conns[topic], t, raw)
    return bag


def _metadata(bag: Path) -> dict:
    info = YAML(typ='safe').load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    for key in ('custom_data', 'relative_file_paths', 'files'):
        info.pop(key, None)
    return info


def _both_ways(src: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, **kwargs) -> tuple:
    """(report, output) of restamp_bag a chunk at a time, then message by message (its chunk path
    checked taken, then turned off)."""
    taken = []
    chunked = restamp._copy_chunks

    def spy(*args, **kw):
        taken.append(True)
        return chunked(*args, **kw)

    monkeypatch.setattr(restamp, '_copy_chunks', spy)
    fast = restamp_bag(src, tmp_path / 'chunks', storage='mcap', **kwargs)
    assert taken, 'the chunk path was not taken'
    monkeypatch.setattr(restamp, '_chunked', lambda *a: None)
    slow = restamp_bag(src, tmp_path / 'messages', storage='mcap', **kwargs)
    return fast, slow


CASES = {
    'offset, record times moved': dict(corrections={ARRAYS: ClockCorrection(offset_ns=37_400_000)},
                                       record_time='shift'),
    'skew rewrites evt3 time words': dict(corrections={EVT3: ClockCorrection(offset_ns=-2_000_000, skew_ppm=80.0,
                                                                             anchor_ns=1_700_000_000_000_000_000)},
                                          reference=ARRAYS, record_time='shift'),
    'past the re-anchoring limit, record times kept': dict(corrections={ARRAYS: ClockCorrection(
        offset_ns=3_000_000_000)}, record_time='keep'),
    'record times moved out of range': dict(corrections={ARRAYS: ClockCorrection(offset_ns=10**9)},
                                            record_time='shift'),
}


@pytest.mark.parametrize('case', list(CASES))
def test_chunk_by_chunk_is_message_by_message(mixed, tmp_path, monkeypatch, case):
    kwargs = {'reference': EVT3, **CASES[case]}
    fast, slow = _both_ways(mixed[case == 'record times moved out of range'], tmp_path, monkeypatch, **kwargs)
    assert fast.topics == slow.topics
    assert bag_digest(tmp_path / 'chunks') == bag_digest(tmp_path / 'messages')
    assert _metadata(tmp_path / 'chunks') == _metadata(tmp_path / 'messages')
    assert fast.topics[EVT3].unchanged_bad > 0 and fast.topics[EVT3].first_error
    assert fast.topics[ARRAYS].unchanged_bad > 0 and fast.topics[ARRAYS].restamped > 0
    if case == 'record times moved out of range':  # the cut EventArray, and the last second's
        assert 1 < fast.topics[ARRAYS].unchanged_bad < fast.topics[ARRAYS].messages_in / 2


@pytest.mark.parametrize('name', ['libcaer_cmp_mcap', 'evk4_hd'])
def test_real_recordings_chunk_by_chunk(real_data, tmp_path, monkeypatch, name):
    src = real_data / name
    if restamp.storage_of(src) != 'mcap':  # an mcap copy of it first, message by message
        restamp_bag(src, tmp_path / 'input', corrections={}, reference='/event_camera/events', storage='mcap')
        src = tmp_path / 'input'
    corr = {'/event_camera/events': ClockCorrection(offset_ns=1_500_000_000, skew_ppm=-30.0, anchor_ns=0)}
    fast, slow = _both_ways(src, tmp_path, monkeypatch, corrections=corr, reference='host')
    assert fast.topics == slow.topics and fast.bad == 0
    assert bag_digest(tmp_path / 'chunks') == bag_digest(tmp_path / 'messages')


def test_chunks_are_written_as_rosbags_writes_them(mixed, tmp_path):
    """The same messages, chunked alike, through rosbags' writer one at a time and through
    ``write_chunk``: the same mcap file, byte for byte."""
    with BagReader(mixed[0]) as reader:
        (storage,) = reader.mcap_storages() or [None]
        assert storage is not None
        topics = {c.id: c.topic for c in storage.connections}
        chunks = [(bytes(c.data), c.rows.copy()) for c in mcapchunks.chunks(storage, name='mixed')]
    outputs = []
    for way in ('rosbags', 'chunks'):
        (tmp_path / way).mkdir()
        out = tmp_path / way / 'bag'  # one name: the metadata names the file
        with BagWriter(out, storage='mcap') as writer:
            types = ((EVT3, EVENT_PACKET), (ARRAYS, DVS_EVENT_ARRAY), (OTHER, 'std_msgs/msg/String'))
            conns = {topic: writer.add_topic(topic, msgtype) for topic, msgtype in types}
            ids = {cid: conns[topic].id for cid, topic in topics.items()}
            for data, rows in chunks:
                rows[:, mcapchunks.ROW_CHANNEL] = [ids[c] for c in rows[:, mcapchunks.ROW_CHANNEL]]
                if way == 'rosbags':
                    by_id = {c.id: c for c in conns.values()}
                    for off, length, log, cid in rows.tolist():
                        writer.write(by_id[cid], log, data[off:off + length])
                    batch = writer._batch  # the input's chunk boundaries
                    assert isinstance(batch, _McapRecords)
                    mcap_writer = batch.storage
                    if mcap_writer.chunk.msgs:  # (rosbags closed it itself when it passed 1 MiB)
                        mcap_writer.close_chunk()
                    continue
                buffer = bytearray()
                logs = rows[:, mcapchunks.ROW_LOG].copy()
                size, offsets = mcapchunks.build(mcapchunks.Chunk(data, rows), rows, logs,
                                                 np.full(len(rows), NO_STAMP), [None] * len(rows), out=buffer)
                writer.write_chunk(bytes(buffer[:size]), rows[:, mcapchunks.ROW_CHANNEL], logs, offsets)
        outputs.append((out / 'bag.mcap').read_bytes() + (out / 'metadata.yaml').read_bytes())
    assert len(chunks) > 1 and outputs[0] == outputs[1]


def test_a_bag_whose_chunks_overlap_is_copied_message_by_message(tmp_path, monkeypatch):
    """Chunks out of time order: read in file order they would not be in the reader's order, so the
    copy goes message by message, and gives the reader's order."""
    src = tmp_path / 'in'
    with BagWriter(src, storage='mcap') as writer:
        conn = writer.add_topic(OTHER, 'std_msgs/msg/String')
        for t in (50, 60, 10, 20):
            writer.write(conn, t, b'\x00\x01\x00\x00' + bytes(600_000))  # a chunk of about two messages each
    with BagReader(src) as reader:
        assert reader.mcap_storages() is None
    monkeypatch.setattr(restamp, '_copy_chunks', lambda *a, **k: pytest.fail('chunk path taken'))
    restamp_bag(src, tmp_path / 'out', corrections={}, reference='host', storage='mcap')
    with BagReader(tmp_path / 'out') as reader:
        assert [t for _, t, _ in reader.messages()] == [10, 20, 50, 60]
