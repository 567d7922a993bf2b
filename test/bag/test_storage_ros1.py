"""A ROS 1 bag restamped into a ROS 1 bag a chunk at a time (``restamp._copy_chunks``, ``storage_ros1``)
gives what restamping it message by message gives: the same messages, bytes, record times and order
and the same report, with malformed messages among real ones, under the cases of ``chunkcopies``.
Its chunks are cut where rosbags' writer cuts them and written as it writes them, byte for byte,
and once written keep no entry per message. Odd record headers and damaged compressed chunks are
read, or refused, as the message path reads or refuses them."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from evsync_ros.bag import records, storage_ros1
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.storage_ros1 import ChunkedWriter, StreamingRos1
from evsync_ros.errors import BagError
from evsync_testing.chunkcopies import ARRAYS, CASES, EVT3, both_ways, mixed_rows, same_both_ways, write_mixed
from evsync_testing.crafted import edit_ros1_messages
from evsync_testing.digest import bag_digest


@pytest.fixture(scope='module')
def mixed(real_data, tmp_path_factory):
    rows = mixed_rows(real_data)
    folder = tmp_path_factory.mktemp('mixed1')
    return write_mixed(folder / 'in.bag', rows), write_mixed(folder / 'late.bag', rows, late=True)


@pytest.mark.parametrize('case', list(CASES))
def test_chunk_by_chunk_is_message_by_message(mixed, tmp_path, monkeypatch, case):
    kwargs = {'reference': EVT3, **CASES[case]}
    src = mixed[case == 'record times moved out of range']
    fast, slow, chunks, messages = both_ways(src, tmp_path, monkeypatch, **kwargs)
    assert fast.topics == slow.topics
    assert bag_digest(chunks) == bag_digest(messages)
    assert fast.topics[EVT3].unchanged_bad > 0 and fast.topics[EVT3].first_error
    assert fast.topics[ARRAYS].unchanged_bad > 0 and fast.topics[ARRAYS].restamped > 0


def test_chunks_are_cut_and_written_as_rosbags_writes_them(mixed, tmp_path):
    """The same records through rosbags' own writer, through ``ChunkedWriter.write`` one at a time
    and through ``add_records`` a chunk's worth at a time, or the two by turns: the same file, byte for
    byte (a small threshold, so that many chunks are cut inside the batches); a chunk
    ``ChunkedWriter`` has written keeps a count per connection, no entries."""
    reader = BagReader(mixed[0])
    with reader:
        (part,) = reader.parts() or []
        assert isinstance(part.file, StreamingRos1)
        conns = part.file.connections
        chunks = [(bytes(c.data), c.rows.copy()) for c in storage_ros1.chunks(part.file)]
    files = []
    for way in ('rosbags', 'write', 'add_records', 'by turns'):
        path = tmp_path / f'{way}.bag'
        with (Writer if way == 'rosbags' else ChunkedWriter)(path) as writer:
            writer.chunk_threshold = 20_000
            out = {c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest,
                                               latching=getattr(c.ext, "latching", None)) for c in conns}
            for i, (data, rows) in enumerate(chunks):
                if way in ('rosbags', 'write') or (way == 'by turns' and i % 2):
                    for off, length, t, cid in rows.tolist():
                        writer.write(out[cid], t, data[off:off + length])
                    continue
                ids = np.array([out[c].id for c in rows[:, records.ROW_CHANNEL].tolist()], np.int64)
                buffer = bytearray()
                size, offsets = records.build(records.Chunk(data, rows), rows, rows[:, records.ROW_LOG],
                                              np.full(len(rows), records.NO_STAMP), [None] * len(rows), out=buffer,
                                              ros1=True)
                assert isinstance(writer, ChunkedWriter)
                writer.add_records(bytes(buffer[:size]), ids, rows[:, records.ROW_LOG].copy(), offsets)
            written = [c for c in writer.chunks if c.pos != -1]
            assert len(written) > 10
            assert way == 'rosbags' or all(isinstance(v, range) for c in written for v in c.connections.values())
        files.append(path.read_bytes())
    assert files[0] == files[1] == files[2] == files[3]


def test_a_damaged_chunk_is_a_bag_error_naming_the_bag(mixed, tmp_path):
    data = bytearray(mixed[0].read_bytes())
    with BagReader(mixed[0]) as reader:
        (part,) = reader.parts() or []
        assert isinstance(part.file, StreamingRos1)
        first = next(storage_ros1.chunks(part.file))
        at = data.find(bytes(first.data[:64]))
    data[at + 1] = 0xFF  # the first record's header length, now past the chunk
    broken = tmp_path / 'broken.bag'
    broken.write_bytes(bytes(data))
    with BagReader(broken) as reader, pytest.raises(BagError, match='broken.bag'):
        (part,) = reader.parts() or []
        assert isinstance(part.file, StreamingRos1)
        next(storage_ros1.chunks(part.file))


def _status_bag(path, *, compression=None):
    """A ROS 1 bag of 199 std_msgs/String messages, its chunks compressed with ``compression``."""
    writer = Writer(path)
    if compression is not None:
        writer.set_compression(compression)
    writer.open()
    conn = writer.add_connection('/status', 'std_msgs/msg/String', typestore=get_typestore(Stores.ROS1_NOETIC))
    for t in range(1, 200):
        writer.write(conn, t * 1000, b'\x02\x00\x00\x00hi' * 20)
    writer.close()
    return path


EDITS = {
    'an op field of two bytes (its first is the op)': lambda fields: [b'op=\x02\x00' if f == b'op=\x02' else f
                                                                        for f in fields],
    'a header field without "="': lambda fields: [*fields, b'junkfield'],
    'a message of a connection the index does not know, without a time': lambda fields: [
        b'conn=' + struct.pack('<I', 77) if f.startswith(b'conn=') else f
        for f in fields if not f.startswith(b'time=')],
    'a message without a conn': lambda fields: [f for f in fields if not f.startswith(b'conn=')],
}


@pytest.mark.parametrize('name', list(EDITS))
def test_odd_record_headers_are_read_as_the_message_path_reads_them(tmp_path, monkeypatch, name):
    bag = edit_ros1_messages(_status_bag(tmp_path / 'plain.bag'), tmp_path / 'in.bag', EDITS[name])
    same_both_ways(bag, tmp_path, monkeypatch, chunked=True, corrections={}, reference='host')


@pytest.mark.parametrize('compression', [Writer.CompressionFormat.BZ2, Writer.CompressionFormat.LZ4])
def test_a_damaged_compressed_chunk_is_a_bag_error_either_way(tmp_path, monkeypatch, compression):
    bag = _status_bag(tmp_path / 'plain.bag', compression=compression)
    data = bytearray(bag.read_bytes())
    at = data.index(b'compression=' + compression.name.lower().encode())
    data[at + 200:at + 260] = bytes(b ^ 0xFF for b in data[at + 200:at + 260])
    (tmp_path / 'in.bag').write_bytes(bytes(data))
    assert same_both_ways(tmp_path / 'in.bag', tmp_path, monkeypatch, chunked=True, corrections={},
                          reference='host') == 'BagError'
