"""An mcap bag restamped into mcap a chunk at a time (``restamp._copy_chunks``, ``storage_mcap``) gives
what restamping it message by message gives: the same messages, bytes, record times and order, the
same report (counts, bad messages and the first error) and the same metadata, on real recordings
with malformed messages among them, under an offset, a skew that rewrites evt3 time words, record
times kept or moved, and record times moved out of range. The chunks it writes are byte for byte
those rosbags' own writer makes of the same messages; a bag whose chunks overlap in time is copied
message by message. What rosbags' writer never writes but files can hold (crafted mcap files) is
read as rosbags' reader reads it, or left to the message path; a damaged chunk is refused either way."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2.storage_mcap import McapReader
from ruamel.yaml import YAML

from evsync_ros.bag import records, restamp, storage_mcap
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.records import NO_STAMP
from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.bag.storage import Storage, output_storage
from evsync_ros.bag.writer import BagWriter, _McapRecords
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.errors import BagError
from evsync_testing import crafted
from evsync_testing.chunkcopies import ARRAYS, CASES, EVT3, OTHER, both_ways, mixed_rows, same_both_ways, write_mixed
from evsync_testing.crafted import MCAP_CASES, STRING
from evsync_testing.digest import bag_digest
from msg_adapters.definitions import DVS_EVENT_ARRAY, EVENT_PACKET


@pytest.fixture(scope='module')
def mixed(real_data, tmp_path_factory) -> tuple[Path, Path]:
    """``chunkcopies``' mixed bag in mcap, and with late record times."""
    rows = mixed_rows(real_data)
    folder = tmp_path_factory.mktemp('mixed')
    return write_mixed(folder / 'in', rows), write_mixed(folder / 'late', rows, late=True)


def _metadata(bag: Path) -> dict:
    info = YAML(typ='safe').load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    for key in ('custom_data', 'relative_file_paths', 'files'):
        info.pop(key, None)
    return info


@pytest.mark.parametrize('case', list(CASES))
def test_chunk_by_chunk_is_message_by_message(mixed, tmp_path, monkeypatch, case):
    kwargs = {'reference': EVT3, **CASES[case]}
    src = mixed[case == 'record times moved out of range']
    fast, slow, chunks, messages = both_ways(src, tmp_path, monkeypatch, storage='mcap', **kwargs)
    assert fast.topics == slow.topics
    assert bag_digest(chunks) == bag_digest(messages)
    assert _metadata(chunks) == _metadata(messages)
    assert fast.topics[EVT3].unchanged_bad > 0 and fast.topics[EVT3].first_error
    assert fast.topics[ARRAYS].unchanged_bad > 0 and fast.topics[ARRAYS].restamped > 0
    if case == 'record times moved out of range':  # the cut EventArray, and the last second's
        assert 1 < fast.topics[ARRAYS].unchanged_bad < fast.topics[ARRAYS].messages_in / 2


@pytest.mark.parametrize('name', ['libcaer_cmp_mcap', 'evk4_hd'])
def test_real_recordings_chunk_by_chunk(real_data, tmp_path, monkeypatch, name):
    src = real_data / name
    if output_storage(src) is not Storage.MCAP:  # an mcap copy of it first, message by message
        restamp_bag(src, tmp_path / 'input', corrections={}, reference='/event_camera/events', storage='mcap')
        src = tmp_path / 'input'
    corr = {'/event_camera/events': ClockCorrection(offset_ns=1_500_000_000, skew_ppm=-30.0, anchor_ns=0)}
    fast, slow, chunks, messages = both_ways(src, tmp_path, monkeypatch, corrections=corr, reference='host',
                                             storage='mcap')
    assert fast.topics == slow.topics and fast.bad == 0
    assert bag_digest(chunks) == bag_digest(messages)


def test_chunks_are_written_as_rosbags_writes_them(mixed, tmp_path):
    """The same messages, chunked alike, through rosbags' writer one at a time and through
    ``write_chunk``: the same mcap file, byte for byte."""
    with BagReader(mixed[0]) as reader:
        (part,) = reader.parts() or []
        assert isinstance(part.file, McapReader)
        topics = part.conns
        chunks = [(bytes(c.data), c.rows.copy()) for c in storage_mcap.chunks(part.file, topics, name='mixed')]
    outputs = []
    for way in ('rosbags', 'chunks'):
        (tmp_path / way).mkdir()
        out = tmp_path / way / 'bag'  # one name: the metadata names the file
        with BagWriter(out, storage='mcap') as writer:
            types = ((EVT3, EVENT_PACKET), (ARRAYS, DVS_EVENT_ARRAY), (OTHER, 'std_msgs/msg/String'))
            conns = {topic: writer.add_topic(topic, msgtype) for topic, msgtype in types}
            ids = {cid: conns[c.topic].id for cid, c in topics.items()}
            for data, rows in chunks:
                rows[:, records.ROW_CHANNEL] = [ids[c] for c in rows[:, records.ROW_CHANNEL]]
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
                logs = rows[:, records.ROW_LOG].copy()
                size, offsets = records.build(records.Chunk(data, rows), rows, logs,
                                                 np.full(len(rows), NO_STAMP), [None] * len(rows), out=buffer)
                writer.write_chunk(bytes(buffer[:size]), rows[:, records.ROW_CHANNEL], logs, offsets)
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
        (part,) = reader.parts() or []
        assert isinstance(part.file, McapReader) and not storage_mcap.in_order(part.file, part.conns)
    monkeypatch.setattr(restamp, '_copy_chunks', lambda *a, **k: pytest.fail('chunk path taken'))
    restamp_bag(src, tmp_path / 'out', corrections={}, reference='host', storage='mcap')
    with BagReader(tmp_path / 'out') as reader:
        assert [t for _, t, _ in reader.messages()] == [10, 20, 50, 60]


@pytest.mark.parametrize('name', list(MCAP_CASES))
def test_crafted_mcap_is_read_as_rosbags_reads_it(tmp_path, monkeypatch, name):
    """What rosbags' writer never writes but an mcap file can hold: the chunk path reads it as the
    message path (rosbags' reader) does, or leaves it to that path, or both refuse it: a damaged
    file, and one whose messages the readers pass over (``crafted.PASSED_OVER``: no output that
    lacks them is left)."""
    chunked, damage = crafted.mcap_case(tmp_path / 'in', name)
    corrections = {'/events': ClockCorrection(offset_ns=1000)} if MCAP_CASES[name][0][0][1] == '/events' else {}
    outcome = same_both_ways(tmp_path / 'in', tmp_path, monkeypatch, chunked=chunked, corrections=corrections,
                             reference='host', storage='mcap')
    assert (outcome == 'BagError') == (damage or name in crafted.PASSED_OVER)
    if outcome == 'BagError':  # no output, not even a hidden partial one, is left by either way
        assert sorted(p.name for p in tmp_path.iterdir()) == ['in']


def test_a_channel_the_metadata_offers_otherwise_is_refused_both_ways(tmp_path, monkeypatch):
    """metadata.yaml offers the topic with other QoS than the file's channel: rosbags matches a
    file's channels to the bag's topics by QoS too, and would yield none of its messages. The bag is
    refused (``BagReader``, as it opens), by the chunk path and the message path alike, not restamped
    without them."""
    with BagWriter(tmp_path / 'in', storage='mcap') as writer:
        conn = writer.add_topic('/s', 'std_msgs/msg/String', offered_qos_profiles=[QOS])
        for t in (10, 20, 30):
            writer.write(conn, t, STRING)
    meta = tmp_path / 'in' / 'metadata.yaml'
    meta.write_text(meta.read_text().replace('reliability: reliable', 'reliability: best_effort'))
    assert same_both_ways(tmp_path / 'in', tmp_path, monkeypatch, corrections={}, reference='host',
                          storage='mcap') == 'BagError'
    with pytest.raises(BagError, match=re.escape("3 messages of /s in in.mcap, whose type or QoS there")):
        BagReader(tmp_path / 'in').__enter__()


_T0 = QosTime(0, 0)
QOS = Qos(QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE, QosDurability.VOLATILE, _T0, _T0,
          QosLiveliness.AUTOMATIC, _T0, avoid_ros_namespace_conventions=False)
