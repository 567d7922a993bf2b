"""restamp_bag end to end on real rosbag2 files: counts, untouched topics, shifted times, refusals."""

import json
from typing import Any

import numpy as np
import pytest
from rosbags.interfaces import Connection, ConnectionExtRosbag2, Qos
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from evsync_ros.bag.estimate import estimate_bag, read_event_times
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.restamp import load_offsets, restamp_bag
from evsync_ros.bag.writer import BagWriter
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.errors import BagError, ParameterError
from evsync_ros.sim.pixelsim import preset, simulate
from evsync_ros.sim.simbag import write_rig
from evsync_testing.messages import packet_bytes
from msg_adapters.cdr import read_stamp
from msg_adapters.event_packet import EventPacketDecoder

STRING = 'std_msgs/msg/String'


def qos_of(conn: Connection) -> list[Qos]:
    """A rosbag2 topic's offered QoS profiles."""
    assert isinstance(conn.ext, ConnectionExtRosbag2)
    return conn.ext.offered_qos_profiles


@pytest.fixture(scope='module')
def mixed_bag(tmp_path_factory):
    """A simulated mixed-models rig (evt3 and dvs topics) plus an unrelated topic and one broken packet."""
    d = tmp_path_factory.mktemp('mixed')
    rig = preset('mixed-models', seed=3, duration_s=12)
    truth = write_rig(rig, simulate(rig), d / 'sim')
    store = get_typestore(Stores.ROS2_JAZZY)
    msgdef, _ = store.generate_msgdef(STRING, ros_version=2)
    Text = store.types[STRING]
    with BagReader(d / 'sim') as reader, BagWriter(d / 'mixed', storage='mcap') as writer:
        conns = {c.topic: writer.add_topic(c.topic, c.msgtype, msgdef=c.msgdef.data, rihs01=c.digest,
                                           offered_qos_profiles=qos_of(c))
                 for c in reader.connections}
        notes = writer.add_topic('/notes', STRING, msgdef=msgdef, rihs01=store.hash_rihs01(STRING))
        for i, (conn, t, raw) in enumerate(reader.messages()):
            writer.write(conns[conn.topic], t, raw)
            if i % 100 == 0:
                writer.write(notes, t, bytes(store.serialize_cdr(Text(data=f'note {i}'), STRING)))
            if i == 1000:  # a packet the adapter cannot read, on an event topic
                writer.write(conns[rig.reference], t, packet_bytes('evt3', b'\x01\x02\x03')[:-9])
    return d / 'mixed', rig, truth


def messages(bag):
    with BagReader(bag) as reader:
        return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]


def by_topic(msgs, topic):
    return [(t, raw) for top, t, raw in msgs if top == topic]


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_event_topics_move_and_everything_else_is_copied(tmp_path, mixed_bag, storage):
    bag, rig, truth = mixed_bag
    cams = [c['topic'] for c in truth['cameras'] if c['topic'] != rig.reference]
    corrections = {cams[0]: ClockCorrection(offset_ns=1_500_000_123, skew_ppm=25.0, anchor_ns=10**18),
                   cams[1]: ClockCorrection(offset_ns=-7_000_000), rig.reference: ClockCorrection(offset_ns=0)}
    rep = restamp_bag(bag, tmp_path / 'out', corrections=corrections, reference=rig.reference, storage=storage)
    before, after = messages(bag), messages(tmp_path / 'out')
    assert sorted({t for t, _, _ in before}) == sorted(rep.topics)
    for topic in rep.topics:
        assert len(by_topic(before, topic)) == len(by_topic(after, topic)) == rep.topics[topic].messages_out
    assert by_topic(before, '/notes') == by_topic(after, '/notes')  # bytes and record times
    ref_in, ref_out = by_topic(before, rig.reference), by_topic(after, rig.reference)
    # the reference: no correction, but the stamp rule (its first event's time); its broken packet
    # written unchanged and counted; record times and payloads kept
    assert [t for t, _ in ref_in] == [t for t, _ in ref_out]
    assert [raw[12:] for _, raw in ref_in] == [raw[12:] for _, raw in ref_out]
    ref = rep.topics[rig.reference]
    assert ref.restamped == ref.messages_in - 1 and ref.unchanged_bad == rep.bad == 1
    times_in, _ = read_event_times(bag, topics=cams)
    times_out, _ = read_event_times(tmp_path / 'out', topics=cams)
    for topic in cams:
        expected = corrections[topic].apply(times_in[topic])
        assert np.abs(times_out[topic] - expected).max() <= 1_000  # per message: skew over <1 ms of events
        # record timestamps: moved with header.stamp only where headers carry the recorder's clock
        moved = rep.topics[topic].record_shifted
        rec_in = [t for t, _ in by_topic(before, topic)]
        rec_out = [t for t, _ in by_topic(after, topic)]
        if moved:
            assert all(abs(o - corrections[topic].apply_one(i)) < 1_000_000 for i, o in zip(rec_in, rec_out))
        else:
            assert rec_in == rec_out
    with Reader(bag) as r1, Reader(tmp_path / 'out') as r2:  # types, definitions, QoS carried over
        keep = {c.topic: (c.msgtype, c.msgdef.data, c.digest, qos_of(c)) for c in r1.connections}
        assert keep == {c.topic: (c.msgtype, c.msgdef.data, c.digest, qos_of(c)) for c in r2.connections}


def test_an_unreadable_event_message_is_written_unchanged_and_counted(tmp_path, mixed_bag):
    bag, rig, _ = mixed_bag
    rep = restamp_bag(bag, tmp_path / 'out', corrections={rig.reference: ClockCorrection(offset_ns=5)},
                      reference=rig.reference)
    t = rep.topics[rig.reference]
    assert t.unchanged_bad == 1 and t.restamped == t.messages_in - 1 and 'message' in t.first_error
    assert rep.bad == 1 and t.messages_out == t.messages_in


def test_restamped_bag_estimates_to_zero(tmp_path, mixed_bag):
    bag, rig, _ = mixed_bag
    est = estimate_bag(bag, reference=rig.reference)
    assert all(c.accepted for c in est.rig.cameras)
    assert est.reports[rig.reference].undecodable == 1  # the broken packet, counted
    restamp_bag(bag, tmp_path / 'out', corrections={c.topic: c.correction for c in est.rig.cameras},
                reference=rig.reference)
    again = estimate_bag(tmp_path / 'out', reference=rig.reference)
    assert max(abs(c.offset_ns) for c in again.rig.cameras) < 50_000


def test_refusals_leave_the_input_and_no_output(tmp_path, mixed_bag):
    bag, rig, _ = mixed_bag
    before = messages(bag)
    (tmp_path / 'taken').mkdir()
    with pytest.raises(BagError, match='refusing to overwrite'):
        restamp_bag(bag, tmp_path / 'taken', corrections={}, reference=rig.reference)
    with pytest.raises(BagError, match='must not be the input'):
        restamp_bag(bag, bag / 'inside', corrections={}, reference=rig.reference)
    with pytest.raises(BagError, match='/notes'):  # not an event type
        restamp_bag(bag, tmp_path / 'x', corrections={'/notes': ClockCorrection(offset_ns=1)}, reference=rig.reference)

    def boom(done, total):
        raise RuntimeError('disk full')

    with pytest.raises(RuntimeError, match='disk full'):
        restamp_bag(bag, tmp_path / 'failed', corrections={}, reference=rig.reference, progress=boom)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['taken']  # nothing partial left behind
    assert messages(bag) == before


def test_offsets_json_is_checked(tmp_path):
    good: dict[str, Any] = {'reference': '/a', 'cameras': [
        {'topic': '/a', 'offset_ns': 0, 'skew_ppm': 0.0, 'anchor_ns': 0},
        {'topic': '/b', 'offset_ns': 12, 'skew_ppm': 3.5, 'anchor_ns': 7}]}
    (tmp_path / 'good.json').write_text(json.dumps(good))
    assert load_offsets(tmp_path / 'good.json') == (
        '/a', {'/a': ClockCorrection(offset_ns=0), '/b': ClockCorrection(offset_ns=12, skew_ppm=3.5, anchor_ns=7)})
    for name, text in [('notjson', '{'), ('noref', json.dumps({**good, 'reference': '/z'})),
                       ('float', json.dumps({**good, 'cameras': [{**good['cameras'][1], 'offset_ns': 1.5}]})),
                       ('missing', json.dumps({'cameras': []}))]:
        (tmp_path / f'{name}.json').write_text(text)
        with pytest.raises(ParameterError, match=f'{name}.json'):
            load_offsets(tmp_path / f'{name}.json')


@pytest.mark.parametrize('name', ['evt3_sqlite3', 'libcaer_cmp_mcap'])
def test_real_recordings_restamp_both_ways(tmp_path, real_data, name):
    bag = real_data / name
    topic = '/event_camera/events'
    shift = ClockCorrection(offset_ns=1_500_000_000)
    rep = restamp_bag(bag, tmp_path / 'out', corrections={topic: shift}, reference=topic)
    assert rep.storage == ('mcap' if 'mcap' in name else 'sqlite3') and rep.bad == 0
    t_in, r_in = read_event_times(bag)
    t_out, r_out = read_event_times(tmp_path / 'out')
    assert r_out[topic].messages == r_in[topic].messages and r_out[topic].events == r_in[topic].events
    np.testing.assert_array_equal(t_out[topic], t_in[topic] + 1_500_000_000)
    back = restamp_bag(tmp_path / 'out', tmp_path / 'back', corrections={topic: shift.inverse()}, reference=topic)
    assert back.bad == 0
    returned, original = [raw for _, _, raw in messages(tmp_path / 'back')], [raw for _, _, raw in messages(bag)]
    # every byte back but header.stamp (the host's arrival), which became the time of the first event
    # that a consumer joining at that message decodes
    assert len(returned) == len(original)
    stream = EventPacketDecoder()
    for b, a in zip(returned, original):
        t, joining = stream.decode(a)[1].t, EventPacketDecoder().decode(a)[1].t.size
        first = t[t.size - joining] if joining else t[0] if t.size else read_stamp(a)
        assert b[:4] == a[:4] and b[12:] == a[12:] and read_stamp(b) == first


@pytest.mark.parametrize('anchor_s', [0.0, -600.0, 3600.0])
def test_a_skew_reaches_every_event_of_the_real_evt3_recording(tmp_path, real_data, anchor_s):
    # anchor_s: where the line is anchored against the bag's first event: there, or far from it (offsets
    # saved by the live node or estimated from another bag of the rig: the bag starts late on the line)
    bag = real_data / 'evt3_sqlite3'
    topic = '/event_camera/events'
    t_in, _ = read_event_times(bag)
    drift = ClockCorrection(offset_ns=-2_000_000, skew_ppm=80.0, anchor_ns=int(t_in[topic][0]) + int(anchor_s * 1e9))
    rep = restamp_bag(bag, tmp_path / 'out', corrections={topic: drift}, reference=topic)
    assert rep.bad == 0
    t_out, r_out = read_event_times(tmp_path / 'out')
    assert not r_out[topic].anomalies or r_out[topic].anomalies == read_event_times(bag)[1][topic].anomalies
    assert np.abs(t_out[topic] - drift.apply(t_in[topic])).max() <= 1_000  # microsecond time words
