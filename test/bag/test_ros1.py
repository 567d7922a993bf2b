"""ROS 1 bags: estimate, restamp and report read them as they read rosbag2, and restamp writes them.

The ROS 1 bags here are made by rosbags' own converter (``rosbags.convert``) from simulated rosbag2
rigs, and the outputs are read back by rosbags' own ROS 1 reader: the results must equal those of
the rosbag2 path on the same recording.
"""

import hashlib
import json
import struct
from pathlib import Path
from typing import Any

import pytest
from rosbags.convert.converter import convert
from rosbags.interfaces import Connection, ConnectionExtRosbag1, ConnectionExtRosbag2, QosDurability
from rosbags.rosbag1 import Reader as Ros1Reader
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.typesys import Stores, get_typestore

from evsync_ros.bag import ros1
from evsync_ros.bag.estimate import estimate_bag
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.restamp import LATCHED, restamp_bag
from evsync_ros.bag.storage_ros1 import StreamingRos1
from evsync_ros.bag.writer import BagWriter
from evsync_ros.cli import main as cli
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.errors import BagError
from evsync_ros.sim.pixelsim import preset, simulate
from evsync_ros.sim.simbag import write_rig

STRING = 'std_msgs/msg/String'


def to_ros1_with_rosbags(src: Path, dst: Path) -> None:
    """``src`` (rosbag2) as a ROS 1 bag, by rosbags' converter."""
    convert([src], dst, 'sqlite3', 9, None, 'file', None, None, [], [], [], [])


def to_ros2_with_rosbags(src: Path, dst: Path) -> None:
    convert([src], dst, 'mcap', 9, None, 'file', None, None, [], [], [], [])


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    """A simulated mixed-models rig (evt3 and dvs) with a latched text topic, as rosbag2 and as a ROS 1
    bag made from it by rosbags, whose event headers carry a running seq as a ROS 1 driver's do."""
    d = tmp_path_factory.mktemp('ros1')
    sim = preset('mixed-models', seed=3, duration_s=12)
    truth = write_rig(sim, simulate(sim), d / 'sim')
    store = get_typestore(Stores.ROS2_JAZZY)
    text = store.types[STRING]
    with BagReader(d / 'sim') as reader, BagWriter(d / 'ros2', storage='mcap') as writer:
        conns = {c.topic: writer.add_topic(c.topic, c.msgtype, msgdef=c.msgdef.data, rihs01=c.digest)
                 for c in reader.connections}
        notes = writer.add_topic('/notes', STRING, msgdef=store.generate_msgdef(STRING, ros_version=2)[0],
                                 rihs01=store.hash_rihs01(STRING), offered_qos_profiles=[LATCHED])
        for i, (conn, t, raw) in enumerate(reader.messages()):
            writer.write(conns[conn.topic], t, raw)
            if i % 100 == 0:
                writer.write(notes, t, bytes(store.serialize_cdr(text(data=f'note {i}'), STRING)))
    to_ros1_with_rosbags(d / 'ros2', d / 'plain.bag')
    with_seq(d / 'plain.bag', d / 'rig.bag')
    return d, truth


def with_seq(src: Path, dst: Path) -> None:
    """A copy of ROS 1 bag ``src`` whose messages with a leading Header count seq 1, 2, ... per topic."""
    with Ros1Reader(src) as reader:
        store = ros1.typestore_for(reader.connections)
        writer = Ros1Writer(dst)
        writer.open()
        out = {c.topic: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest,
                                              latching=latching(c)) for c in reader.connections}
        seq: dict[str, int] = {}
        for conn, t, raw in reader.messages():
            data = bytearray(raw)
            if ros1.leading_header(store, conn.msgtype):
                seq[conn.topic] = seq.get(conn.topic, 0) + 1
                data[:4] = struct.pack('<I', seq[conn.topic])
            writer.write(out[conn.topic], t, bytes(data))
        writer.close()


def latching(conn: Connection) -> int:
    assert isinstance(conn.ext, ConnectionExtRosbag1)
    return conn.ext.latching


def cdr_messages(bag: Path) -> list[tuple[str, int, bytes]]:
    with BagReader(bag) as reader:
        return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]


def native_messages(bag: Path) -> list[tuple[str, int, bytes]]:
    with Ros1Reader(bag) as reader:
        return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_ros1_bag_reads_as_the_same_cdr_messages_as_its_rosbag2(rig):
    d, _ = rig
    assert cdr_messages(d / 'plain.bag') == sorted(cdr_messages(d / 'ros2'), key=lambda m: m[1])
    with BagReader(d / 'rig.bag') as reader:
        counts = reader.message_counts()
        assert reader.span_ns > 11 * 10**9
    with BagReader(d / 'ros2') as reader:
        assert counts == reader.message_counts()


def test_estimate_of_a_ros1_bag_equals_that_of_its_rosbag2(rig):
    d, truth = rig
    ros2 = estimate_bag(d / 'ros2', reference=truth['reference'])
    one = estimate_bag(d / 'rig.bag', reference=truth['reference'])
    assert one.rig.as_json() == ros2.rig.as_json()
    for cam in truth['cameras']:
        fit = one.rig.camera(cam['topic'])
        assert fit.accepted
        assert abs(fit.offset_ns - cam['offset_ns']) <= 3 * fit.uncertainty_ns  # within what it says of itself


def test_restamp_ros1_to_ros1_keeps_seq_order_and_every_other_byte(rig, tmp_path):
    d, _ = rig
    before = digest(d / 'rig.bag')
    est = estimate_bag(d / 'rig.bag')
    rep = restamp_bag(d / 'rig.bag', tmp_path / 'out.bag', corrections=est.rig.corrections,
                      reference=est.rig.reference)
    assert rep.storage == 'ros1' and rep.bad == 0
    assert digest(d / 'rig.bag') == before  # the input only read
    src, out = native_messages(d / 'rig.bag'), native_messages(tmp_path / 'out.bag')
    assert [m[0] for m in src] == [m[0] for m in out]  # every message once, in order
    moved = 0
    for (topic, _, a), (_, _, b) in zip(src, out):
        if topic in (est.rig.reference, '/notes'):
            assert a == b
        else:
            assert a[:4] == b[:4]  # the header's seq, kept
            moved += a != b
    assert moved > 1000
    with Ros1Reader(tmp_path / 'out.bag') as reader:  # rosbags' own reader: definitions and latching kept
        conns = {c.topic: c for c in reader.connections}
    with Ros1Reader(d / 'rig.bag') as reader:
        for c in reader.connections:
            assert (conns[c.topic].msgdef, conns[c.topic].digest) == (c.msgdef, c.digest)
            assert latching(conns[c.topic]) == latching(c)
    assert latching(conns['/notes']) == 1


def test_restamp_across_formats_equals_the_rosbag2_path(rig, tmp_path):
    d, _ = rig
    est = estimate_bag(d / 'ros2')
    kw: dict[str, Any] = {'corrections': est.rig.corrections, 'reference': est.rig.reference}
    restamp_bag(d / 'ros2', tmp_path / 'r2r2', **kw)
    restamp_bag(d / 'plain.bag', tmp_path / 'r1r2', **kw)
    restamp_bag(d / 'ros2', tmp_path / 'r2r1.bag', **kw)
    restamp_bag(d / 'plain.bag', tmp_path / 'r1r1.bag', **kw)
    want = sorted(cdr_messages(tmp_path / 'r2r2'), key=lambda m: m[1])
    for out in ('r1r2', 'r2r1.bag', 'r1r1.bag'):
        assert sorted(cdr_messages(tmp_path / out), key=lambda m: m[1]) == want, out
    with BagReader(tmp_path / 'r1r2') as reader:  # a rosbag2 of a ROS 1 input: ROS 2's definitions, latching as QoS
        conns = {c.topic: c for c in reader.connections}
    assert conns['/notes'].msgdef.data.strip() == 'string data'
    notes = conns['/notes'].ext
    assert isinstance(notes, ConnectionExtRosbag2)
    assert notes.offered_qos_profiles[0].durability is QosDurability.TRANSIENT_LOCAL
    # and rosbags' converter reads what restamp wrote, as it would any ROS 1 bag
    to_ros2_with_rosbags(tmp_path / 'r1r1.bag', tmp_path / 'back')
    assert sorted(cdr_messages(tmp_path / 'back'), key=lambda m: m[1]) == want


def test_cli_on_ros1_bags_and_the_report_marks_agreeing_windows(rig, tmp_path, capsys):
    d, truth = rig
    assert cli.main(['estimate', str(d / 'rig.bag'), '--json']) == 0
    doc = json.loads(capsys.readouterr().out)
    assert all(c['accepted'] for c in doc['cameras'])
    assert cli.main(['restamp', str(d / 'rig.bag'), str(tmp_path / 'out.bag')]) == 0
    assert cli.main(['report', str(tmp_path / 'out.bag')]) == 0
    out = capsys.readouterr().out
    for cam in truth['cameras']:
        if cam['topic'] != doc['reference']:
            header = next(line for line in out.splitlines() if line.startswith(f'{cam["topic"]}: '))
            n, agree = header.split(' windows, ')[0].split()[-1], header.split(' windows, ')[1].split()[0]
            assert int(agree) == int(n) > 2, header  # restamped: every window agrees with offset ~0
    assert cli.main(['restamp', str(d / 'rig.bag'), str(tmp_path / 'x.bag'), '--storage', 'mcap']) == 2
    assert 'ROS 1 bag' in capsys.readouterr().err
    assert not (tmp_path / 'x.bag').exists()


def test_unindexed_and_damaged_ros1_bags_are_clear_errors(rig, tmp_path):
    d, _ = rig
    data = bytearray((d / 'rig.bag').read_bytes())
    unindexed = tmp_path / 'unindexed.bag'
    at = data.index(b'index_pos=') + len(b'index_pos=')
    unindexed.write_bytes(bytes(data[:at]) + bytes(8) + bytes(data[at + 8:]))
    with pytest.raises(BagError, match=r'unindexed\.bag.*not indexed.*reindex'):
        estimate_bag(unindexed)
    cut = tmp_path / 'cut.bag'
    cut.write_bytes(bytes(data[: len(data) // 2]))
    with pytest.raises(BagError, match=r'cut\.bag'):
        estimate_bag(cut)
    with pytest.raises(BagError, match=r'cut\.bag'):
        restamp_bag(cut, tmp_path / 'o.bag', corrections={}, reference='/cam0/events')
    assert not (tmp_path / 'o.bag').exists()
    assert not list(tmp_path.glob('.o.bag.*'))  # no partial output left behind


def test_a_message_that_does_not_match_its_definition_is_written_unchanged_and_counted(rig, tmp_path):
    d, truth = rig
    bad = tmp_path / 'bad.bag'
    with Ros1Reader(d / 'rig.bag') as reader:
        writer = Ros1Writer(bad)
        writer.open()
        out = {c.topic: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
               for c in reader.connections}
        victim = None
        for conn, t, raw in reader.messages():
            if victim is None and conn.msgtype == 'dvs_msgs/msg/EventArray':
                victim, raw = conn.topic, raw[:-7]
            writer.write(out[conn.topic], t, raw)
        writer.close()
    est = estimate_bag(bad, reference=truth['reference'])  # counted, and the estimate goes on
    assert est.reports[victim].undecodable == 1 and 'definition' in est.reports[victim].first_error
    assert all(c.accepted for c in est.rig.cameras)
    rep = restamp_bag(bad, tmp_path / 'o.bag', corrections=est.rig.corrections, reference=est.rig.reference)
    assert rep.topics[victim].unchanged_bad == 1 and 'definition' in rep.topics[victim].first_error
    assert sum(t.messages_out for t in rep.topics.values()) == sum(t.messages_in for t in rep.topics.values())
    first = next(i for i, m in enumerate(native_messages(bad)) if m[0] == victim)
    assert native_messages(tmp_path / 'o.bag')[first] == native_messages(bad)[first]  # written unchanged
    rep2 = restamp_bag(bad, tmp_path / 'o2', corrections=est.rig.corrections, reference=est.rig.reference)
    assert rep2.topics[victim].unconvertible == 1 and rep2.bad == 1  # no ROS 2 form: counted, not written
    assert rep2.topics[victim].messages_out == rep2.topics[victim].messages_in - 1


@pytest.mark.parametrize('name', ['dvs128_stereo/fan', 'evt3_sqlite3', 'evk4_hd'])
def test_real_recordings_as_ros1_bags_estimate_and_restamp_as_their_rosbag2(real_data, tmp_path, name):
    src = real_data / name
    to_ros1_with_rosbags(src, tmp_path / 'real.bag')
    ros2, one = estimate_bag(src), estimate_bag(tmp_path / 'real.bag')
    assert one.rig.as_json() == ros2.rig.as_json()
    assert {t: (r.messages, r.events, r.undecodable) for t, r in one.reports.items()} == \
        {t: (r.messages, r.events, r.undecodable) for t, r in ros2.reports.items()}
    shift = {t: ClockCorrection(offset_ns=1_234_567) for t in ros2.reports if t != ros2.rig.reference}
    if not shift:  # one camera: restamp it against itself moved, so that something moves
        shift = {ros2.rig.reference: ClockCorrection(offset_ns=1_234_567)}
    kw: dict[str, Any] = {'corrections': shift, 'reference': ros2.rig.reference}
    restamp_bag(src, tmp_path / 'r2', **kw)
    restamp_bag(tmp_path / 'real.bag', tmp_path / 'r1.bag', **kw)
    assert sorted(cdr_messages(tmp_path / 'r1.bag'), key=lambda m: m[1]) == \
        sorted(cdr_messages(tmp_path / 'r2'), key=lambda m: m[1])


def test_the_header_types_a_ros1_typestore_starts_from_are_ros2_jazzys():
    """``ros1.header_types`` parses the two definitions rather than making Jazzy's whole typestore: they
    must be Jazzy's, field for field."""
    from rosbags.typesys import Stores, get_typestore

    jazzy = get_typestore(Stores.ROS2_JAZZY)
    assert ros1.header_types() == {name: jazzy.fielddefs[name]
                                   for name in ('std_msgs/msg/Header', 'builtin_interfaces/msg/Time')}


def test_a_chunk_longer_than_the_file_is_refused_before_memory_is_taken(rig, tmp_path):
    """A damaged chunk length (here 1.5 GB) is a BagError naming the bag, found before a buffer of
    that size is made (zero-filled, every page of it would be taken)."""
    import tracemalloc

    d, _ = rig
    data = bytearray((d / 'rig.bag').read_bytes())
    with BagReader(d / 'rig.bag') as reader:
        (part,) = reader.parts() or []
        assert isinstance(part.file, StreamingRos1)
        first = bytes(next(part.file.chunks())[:64])
    at = data.index(first) - 4  # the chunk record's data length, just before its data
    struct.pack_into('<I', data, at, 1_500_000_000)
    damaged = tmp_path / 'damaged.bag'
    damaged.write_bytes(bytes(data))
    tracemalloc.start()
    try:
        with BagReader(damaged) as reader, pytest.raises(BagError, match=r'damaged\.bag.*longer than the file'):
            (part,) = reader.parts() or []
            assert isinstance(part.file, StreamingRos1)
            next(part.file.chunks())
        assert tracemalloc.get_traced_memory()[1] < 100_000_000
    finally:
        tracemalloc.stop()
