"""Opening the real recordings with rosbags, including the mcap whose metadata names no storage."""

import dataclasses
import re
import shutil
import sqlite3
import struct
from pathlib import Path

import apsw
import numpy as np
import pytest
from rosbags.rosbag2.storage_mcap import McapReader
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader
from ruamel.yaml import YAML

from evsync_ros.bag.estimate import estimate_bag
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.bag.storage import Storage
from evsync_ros.bag.storage_sqlite3 import connection
from evsync_ros.bag.writer import BagWriter
from evsync_ros.errors import BagError
from evsync_ros.sim.pixelsim import preset, simulate
from evsync_ros.sim.simbag import write_rig
from evsync_testing.crafted import STRING, edit_mcap_channel, edit_ros1_messages, two_topics, without_channel_counts
from msg_adapters.definitions import EVENT_PACKET, event_typestore

TOPIC = '/event_camera/events'


def _packets(bag):
    store = event_typestore()
    with BagReader(bag) as reader:
        assert [(c.topic, c.msgtype) for c in reader.connections] == [(TOPIC, EVENT_PACKET)]
        counts = reader.message_counts()
        msgs = [(ts, store.deserialize_cdr(raw, c.msgtype)) for c, ts, raw in reader.messages()]
    return counts, msgs


def test_evt3_sqlite3_recording_opens_and_deserialises(real_data):
    counts, msgs = _packets(real_data / 'evt3_sqlite3')
    assert counts == {TOPIC: 517} and len(msgs) == 517
    seqs = np.array([m.seq for _, m in msgs])
    assert seqs[0] == 5590 and np.all(np.diff(seqs) == 1)  # none missing
    first = msgs[0][1]
    assert (first.encoding, first.width, first.height, first.time_base) == ('evt3', 640, 480, 0)
    assert not first.is_bigendian and first.events.size % 2 == 0


def test_mcap_recording_with_empty_storage_id_still_opens(real_data):
    bag = real_data / 'libcaer_cmp_mcap'
    meta = YAML(typ='safe').load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['storage_identifier'] == ''  # the very case rosbags' directory reader refuses
    counts, msgs = _packets(bag)
    assert counts == {TOPIC: 100} and len(msgs) == 100
    first = msgs[0][1]
    assert (first.encoding, first.width, first.height) == ('libcaer_cmp', 346, 260)
    assert first.time_base > 0


def test_missing_bag_and_missing_storage_file_are_named(tmp_path, real_data):
    with pytest.raises(BagError, match='no such bag'):
        BagReader(tmp_path / 'nope')
    broken = tmp_path / 'broken'
    broken.mkdir()
    shutil.copy(real_data / 'libcaer_cmp_mcap' / 'metadata.yaml', broken / 'metadata.yaml')
    with pytest.raises(BagError, match='missing'):
        BagReader(broken)


def test_a_connection_a_sqlite3_file_opens_in_another_process_is_its_own_and_closed_on_leaving(tmp_path):
    """Where the bag was opened in another process (``Part.pid``, as a forked process sees it),
    ``storage_sqlite3.connection`` opens the file anew and closes it on leaving, on an error too;
    where it was opened, it is the file's own."""
    bag = tmp_path / 'bag'
    with BagWriter(bag, storage='sqlite3') as writer:
        conn = writer.add_topic('/s', 'std_msgs/msg/String')
        writer.write(conn, 10, STRING)
    with BagReader(bag) as reader:
        (part,) = reader.parts() or []
        storage = part.file
        assert isinstance(storage, Sqlite3Reader) and part.storage is Storage.SQLITE3
        with connection(part) as own:
            assert own is storage.dbconn
        elsewhere = dataclasses.replace(part, pid=-1)
        with connection(elsewhere) as mine:
            assert mine is not storage.dbconn and mine.execute('SELECT count(*) FROM messages').fetchall() == [(1,)]
        with pytest.raises(RuntimeError, match='stopped'), connection(elsewhere) as stopped:
            _stop()
        for closed in (mine, stopped):
            with pytest.raises(apsw.ConnectionClosedError):
                closed.execute('SELECT 1')
        assert storage.dbconn.execute('SELECT count(*) FROM messages').fetchall() == [(1,)]


def test_an_mcap_channel_metadata_yaml_lists_otherwise_is_a_bag_error_naming_it(tmp_path):
    """An mcap channel whose topic metadata.yaml lists with another type: rosbags reads none of its
    messages (a whole camera gone from an estimate, with exit status 0, before this check); refused
    on opening, naming the bag, the file, the topic and how many messages, from the file's statistics."""
    bag = tmp_path / 'bag'
    two_topics(bag, storage='mcap')
    meta = bag / 'metadata.yaml'
    with BagReader(bag) as reader:
        assert sum(1 for _ in reader.messages()) == 6
    text = meta.read_text()
    name_b = text.index('name: /b')
    at = text.index('type: std_msgs/msg/String', name_b)
    meta.write_text(text[:at] + 'type: std_msgs/msg/Strong' + text[at + len('type: std_msgs/msg/String'):])
    said = ('3 messages of /b in bag.mcap, whose type or QoS there (std_msgs/msg/String) is not what '
            'metadata.yaml says (one of them is corrupt, or the file was rewritten under the old metadata.yaml; '
            'without it the files are read alone): rosbags would pass over them unseen')
    with pytest.raises(BagError, match=re.escape(f'{bag}: {said}')), BagReader(bag):
        pass


def test_an_mcap_whose_statistics_give_no_channel_counts_is_read_and_counted_from_its_chunks(tmp_path):
    """The mcap spec lets a file's statistics leave the per-channel counts out ("not available"):
    such a file opens and reads (no message is taken for one of no channel), and what a whole read
    must yield is counted from its chunk indexes."""
    bag = tmp_path / 'bag'
    two_topics(bag, storage='mcap')
    (mcap,) = bag.glob('*.mcap')
    without_channel_counts(mcap)
    with BagReader(bag) as reader:
        (part,) = reader.parts() or []
        storage = part.file
        assert isinstance(storage, McapReader) and storage.statistics is not None
        assert storage.statistics.message_count == 6 and not storage.statistics.channel_message_counts
        assert sum(1 for _ in reader.messages()) == 6
        assert reader.listed() == {'/a': 3, '/b': 3}
        assert str(reader.unread({'/a': 3, '/b': 2})).endswith('messages its index lists could not be read: '
                                                               '1 of the 3 of /b (records the readers pass over: a '
                                                               'damaged record or index, or a layout they cannot read)')
        assert reader.unread({'/a': 3, '/b': 3}) is None


@pytest.fixture(scope='module')
def small_rigs(tmp_path_factory) -> dict[str, Path]:
    """A simulated rig of 4 s as an mcap rosbag2 and as a ROS 1 bag."""
    rig = preset('same-model', seed=5, duration_s=4)
    events = simulate(rig)
    folder = tmp_path_factory.mktemp('rigs')
    write_rig(rig, events, folder / 'mcap', storage='mcap')
    write_rig(rig, events, folder / 'rig.bag', storage='ros1')
    return {'mcap': folder / 'mcap', 'ros1': folder / 'rig.bag'}


def _passed_over(src: Path, dst: Path) -> Path:
    """``src`` with one message whose channel (mcap) or connection (ROS 1) id names none: every reader
    passes over it, rosbags' and the chunk readers alike."""
    if src.suffix == '.bag':
        return edit_ros1_messages(src, dst, lambda fields: [b'conn=' + struct.pack('<I', 99) if f.startswith(b'conn=')
                                                            else f for f in fields])
    shutil.copytree(src, dst)
    (mcap,) = dst.glob('*.mcap')
    edit_mcap_channel(mcap, mcap, channel=99)
    return dst


@pytest.mark.parametrize('storage', ['mcap', 'ros1'])
def test_messages_the_index_lists_and_no_reader_reads_are_refused_not_lost(small_rigs, tmp_path, storage):
    """A message the storage's index lists (mcap statistics, ROS 1 chunk infos) that no reader reads
    (its channel or connection id names none): the restamp, forked and not, and the estimate refuse
    the bag, naming it, the topic and how many of its messages, and leave no output, where they
    used to finish without it (exit status 0)."""
    bag = _passed_over(small_rigs[storage], tmp_path / ('in.bag' if storage == 'ros1' else 'in'))
    said = re.compile(re.escape(f'{bag}: messages its index lists could not be read: ') + r'\d+ of the \d+ of /\S+')
    with BagReader(small_rigs[storage]) as reader:
        topics = {c.topic for c in reader.connections}
    for parallel in (True, False):
        with pytest.raises(BagError, match=said):
            restamp_bag(bag, tmp_path / 'out', corrections={}, reference=sorted(topics)[0], parallel=parallel)
        assert not list(tmp_path.glob('out*')) and not list(tmp_path.glob('.out*'))
    for parallel in (True, False):
        with pytest.raises(BagError, match=said):
            estimate_bag(bag, parallel=parallel)
    estimate_bag(small_rigs[storage])  # the bag as written reads whole


def test_a_ros1_index_whose_messages_name_no_connection_record_is_refused(small_rigs, tmp_path):
    """A ROS 1 index whose chunk infos count a connection that no connection record names: that
    topic's messages would be passed over whole (a camera gone from the estimate and the restamp)."""
    data = bytearray(small_rigs['ros1'].read_bytes())
    (index_pos,) = struct.unpack_from('<Q', data, data.index(b'index_pos=') + 10)
    at = data.index(b'conn=' + struct.pack('<I', 0), index_pos)  # connection 0's record in the index
    data[at + 5:at + 9] = struct.pack('<I', 99)
    bag = tmp_path / 'in.bag'
    bag.write_bytes(bytes(data))
    with pytest.raises(BagError, match=re.escape(f'{bag}: its index lists ') + r'\d+ messages of connection 0 but no '
                       'connection record for them'):
        BagReader(bag).__enter__()


def _stop() -> None:
    raise RuntimeError('stopped')


@pytest.mark.parametrize(('edit', 'said'), [
    ("UPDATE topics SET type='' WHERE name='/b'",
     "3 messages of /b in bag.db3, whose type or QoS there (none) is not what metadata.yaml says"),
    ("UPDATE messages SET topic_id=99 WHERE timestamp=11", "1 messages in bag.db3 whose topic id names no topic"),
])
def test_messages_rosbags_would_pass_over_unseen_are_a_bag_error_naming_them(tmp_path, edit, said):
    """A sqlite3 file's topic that metadata.yaml lists otherwise (rosbags reads none of its messages),
    or rows whose topic id names no topic (rosbags' query joins them out): refused on opening, naming
    the bag and what would be lost, rather than read as if they were not there."""
    bag = tmp_path / 'bag'
    two_topics(bag, storage='sqlite3')
    db = sqlite3.connect(next(bag.glob('*.db3')))
    with db:
        db.execute(edit)
    db.close()
    with pytest.raises(BagError, match=re.escape(f'{bag}: {said}')), BagReader(bag):
        pass
