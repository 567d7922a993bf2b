"""BagWriter writes a rosbag2's messages in batches: its storage file and metadata must be, byte for
byte, what rosbags' own Writer writes from the same messages one at a time (both storages, messages of
every size, out of order, from bytes, bytearray and memoryview, past several batches and mcap chunks)."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin, Writer

from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.writer import BATCH_MESSAGES, BagWriter
from evsync_ros.errors import BagError
from msg_adapters.definitions import DVS_EVENT_ARRAY, EVENT_PACKET

TOPICS = {'/a/events': EVENT_PACKET, '/b/events': DVS_EVENT_ARRAY, '/c/events': EVENT_PACKET}


def messages() -> list[tuple[str, int, bytes | bytearray | memoryview]]:
    rng = np.random.default_rng(7)
    topics = list(TOPICS)
    out: list[tuple[str, int, bytes | bytearray | memoryview]] = []
    t = 1_700_000_000_000_000_000
    for i in range(3 * BATCH_MESSAGES + 17):
        t += int(rng.integers(-2_000_000, 5_000_000))  # now and then earlier than the last
        data = rng.bytes(int(rng.choice([0, 1, 20, 700, 3000, 40_000])))
        kind = i % 3
        out.append((topics[int(rng.integers(3))], t,
                    data if kind == 0 else bytearray(data) if kind == 1 else memoryview(data)))
    return out


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_the_files_are_those_rosbags_writes_message_by_message(tmp_path, storage):
    msgs = messages()
    (tmp_path / 'ours').mkdir()
    (tmp_path / 'theirs').mkdir()
    with BagWriter(tmp_path / 'ours' / 'bag', storage=storage) as ours:
        conns = {topic: ours.add_topic(topic, msgtype) for topic, msgtype in TOPICS.items()}
        for topic, t, raw in msgs:
            ours.write(conns[topic], t, raw)
    theirs = Writer(tmp_path / 'theirs' / 'bag', version=9,
                    storage_plugin=StoragePlugin.SQLITE3 if storage == 'sqlite3' else StoragePlugin.MCAP)
    theirs.open()
    plain = {topic: theirs.add_connection(topic, c.msgtype, msgdef=c.msgdef.data, rihs01=c.digest)
             for topic, c in conns.items()}
    for topic, t, raw in msgs:
        theirs.write(plain[topic], t, bytes(raw))
    theirs.close()
    suffix = '.db3' if storage == 'sqlite3' else '.mcap'
    for name in (f'bag{suffix}', 'metadata.yaml'):
        assert (tmp_path / 'ours' / 'bag' / name).read_bytes() == (tmp_path / 'theirs' / 'bag' / name).read_bytes()
    with BagReader(tmp_path / 'ours' / 'bag') as reader:
        back = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
    assert sorted(back, key=lambda m: m[1]) == sorted(((tp, t, bytes(r)) for tp, t, r in msgs), key=lambda m: m[1])


def test_a_bytearray_changed_after_writing_is_written_as_it_was(tmp_path):
    with BagWriter(tmp_path / 'bag', storage='sqlite3') as writer:
        conn = writer.add_topic('/a/events', EVENT_PACKET)
        buf = bytearray(b'first')
        writer.write(conn, 1, buf)
        buf[:] = b'later'  # before the batch goes in
    with BagReader(tmp_path / 'bag') as reader:
        assert [bytes(raw) for _, _, raw in reader.messages()] == [b'first']


def test_an_unknown_connection_is_refused_as_before(tmp_path):
    with BagWriter(tmp_path / 'other', storage='mcap') as other:
        stranger = other.add_topic('/x', EVENT_PACKET)
    with pytest.raises(BagError, match='writing failed'), BagWriter(tmp_path / 'bag', storage='mcap') as writer:
        writer.add_topic('/a/events', EVENT_PACKET)
        writer.write(stranger, 1, b'x')
    assert not (tmp_path / 'bag').exists()


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap', 'ros1'])
def test_ctrl_c_as_the_bag_opens_leaves_nothing(tmp_path, storage):
    """A KeyboardInterrupt (what Ctrl-C, and evsync's SIGTERM handler, raise) inside the storage's
    open, after the hidden partial directory is made: it is removed, not left for a later run."""
    opens = {Writer.open.__code__, Ros1Writer.open.__code__}

    def interrupt(frame, event, arg):
        if event == 'call' and frame.f_code in opens:
            raise KeyboardInterrupt

    out = tmp_path / ('out.bag' if storage == 'ros1' else 'out')
    sys.settrace(interrupt)
    try:
        with pytest.raises(KeyboardInterrupt), BagWriter(out, storage=storage):
            pass
    finally:
        sys.settrace(None)
    assert list(tmp_path.iterdir()) == []
