"""EventPacket fields read straight from CDR agree with rosbags; malformed bytes get clear errors."""

from typing import Any

import numpy as np
import pytest

from evsync_ros.bag.reader import BagReader
from evsync_ros.errors import MessageError
from msg_adapters.definitions import EVENT_PACKET, event_typestore
from msg_adapters.event_packet import parse_event_packet


@pytest.mark.parametrize('bag', ['evt3_sqlite3', 'libcaer_cmp_mcap'])
def test_fields_agree_with_rosbags_on_every_real_message(real_data, bag):
    store = event_typestore()
    with BagReader(real_data / bag) as reader:
        for _, _, raw in reader.messages():
            msg: Any = store.deserialize_cdr(raw, EVENT_PACKET)
            view = parse_event_packet(raw)
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            assert (view.stamp_ns, view.frame_id, view.height, view.width, view.seq, view.time_base,
                    view.encoding, view.is_bigendian) == (
                stamp, msg.header.frame_id, msg.height, msg.width, msg.seq, msg.time_base,
                msg.encoding, msg.is_bigendian)
            np.testing.assert_array_equal(view.events, msg.events)
            assert int.from_bytes(raw[view.time_base_offset:view.time_base_offset + 8], 'little') == msg.time_base


def _serialized(**fields):
    store = event_typestore()
    Time = store.types['builtin_interfaces/msg/Time']
    Header = store.types['std_msgs/msg/Header']
    Packet = store.types[EVENT_PACKET]
    msg = Packet(header=Header(stamp=Time(sec=5, nanosec=7), frame_id='cam'), height=2, width=3, seq=1,
                 time_base=9, encoding='mono', is_bigendian=False, events=np.zeros(16, np.uint8))
    for k, v in fields.items():
        setattr(msg, k, v)
    return bytes(store.serialize_cdr(msg, EVENT_PACKET))


def test_every_truncation_is_a_clear_error():
    raw = _serialized()
    assert parse_event_packet(raw).events.size == 16
    for cut in range(len(raw)):
        with pytest.raises(MessageError, match='EventPacket'):
            parse_event_packet(raw[:cut])


def test_big_endian_cdr_is_refused():
    raw = bytearray(_serialized())
    raw[1] = 0x00  # CDR_BE representation identifier
    with pytest.raises(MessageError, match='little-endian'):
        parse_event_packet(bytes(raw))


# --- the per-stream decoder and restamping -------------------------------------------------------

from evsync_ros.core.clock import ClockCorrection  # noqa: E402
from evsync_testing.messages import NS, libcaer_payload, mono_payload, packet_bytes  # noqa: E402
from msg_adapters.event_packet import EventPacketDecoder, restamp_event_packet  # noqa: E402


def _real_stream(real_data, bag):
    with BagReader(real_data / bag) as reader:
        return [raw for _, _, raw in reader.messages()]


@pytest.mark.parametrize('bag', ['evt3_sqlite3', 'libcaer_cmp_mcap'])
@pytest.mark.parametrize('d', [1, -1, 2_000_000_123, -86_400 * NS])
def test_restamp_real_stream_by_d_then_minus_d(real_data, bag, d):
    raws = _real_stream(real_data, bag)
    before = EventPacketDecoder()
    times = [before.decode(raw)[1].t for raw in raws]
    there = [restamp_event_packet(raw, ClockCorrection(offset_ns=d)) for raw in raws]
    after = EventPacketDecoder()
    for raw, moved, t in zip(raws, there, times):
        view, ev = after.decode(moved)
        np.testing.assert_array_equal(ev.t, t + d)  # every event, evt3 through its anchor
        src = parse_event_packet(raw)
        # evt3: the stamp carries the anchor, and moves; libcaer: it becomes time_base, on the new timeline
        assert view.stamp_ns == (src.stamp_ns if src.encoding == 'evt3' else src.time_base) + d
        assert bytes(view.events) == bytes(src.events)  # payload untouched
    back = [bytes(restamp_event_packet(m, ClockCorrection(offset_ns=-d))) for m in there]
    if bag == 'evt3_sqlite3':
        assert back == [bytes(r) for r in raws]
    else:  # every byte back but the stamp, which is time_base's now
        for raw, b in zip(raws, back):
            assert b[:4] == bytes(raw[:4]) and b[12:] == bytes(raw[12:])
            assert parse_event_packet(b).stamp_ns == parse_event_packet(raw).time_base


def test_real_evt3_anchor_is_the_first_message_stamp_minus_its_first_sensor_time(real_data):
    dec = EventPacketDecoder()
    raws = _real_stream(real_data, 'evt3_sqlite3')
    view, ev = dec.decode(raws[0])
    assert ev.t[0] == view.stamp_ns  # anchored there
    for raw in raws[1:]:
        view, ev = dec.decode(raw)
        assert abs(int(ev.t[0]) - view.stamp_ns) < 20_000_000  # within host latency of its stamp
    assert dec.anomalies == {}


@pytest.mark.parametrize('encoding', ['libcaer_cmp', 'libcaer', 'mono', 'trigger'])
def test_restamp_moves_time_base_and_stamp_only(encoding):
    # header.stamp (libcaer_driver: the host's arrival time) becomes time_base on the rig's timeline
    raw = packet_bytes(encoding, bytes(16), time_base=5 * NS, stamp_ns=6 * NS)
    out = restamp_event_packet(raw, ClockCorrection(offset_ns=-NS, skew_ppm=100.0, anchor_ns=4 * NS))
    view = parse_event_packet(out)
    assert (view.time_base, view.stamp_ns) == (4 * NS + 100_000, 4 * NS + 100_000)
    assert bytes(out[view.time_base_offset + 8:]) == bytes(raw[view.time_base_offset + 8:])


def test_evt3_zero_time_base_stays_zero():
    raw = packet_bytes('evt3', b'', stamp_ns=NS)
    view = parse_event_packet(restamp_event_packet(raw, ClockCorrection(offset_ns=5)))
    assert (view.time_base, view.stamp_ns) == (0, NS + 5)


def test_rosbags_and_rclpy_read_a_restamped_packet_identically(real_data):
    serialization = pytest.importorskip('rclpy.serialization', reason='rclpy is installed by ./dev setup')
    from event_camera_msgs.msg import EventPacket

    for bag in ('evt3_sqlite3', 'libcaer_cmp_mcap'):
        raw = _real_stream(real_data, bag)[3]
        out = bytes(restamp_event_packet(raw, ClockCorrection(offset_ns=-3_210_987_654)))
        a: Any = event_typestore().deserialize_cdr(out, EVENT_PACKET)
        b = serialization.deserialize_message(out, EventPacket)
        assert (a.header.stamp.sec, a.header.stamp.nanosec, a.header.frame_id, a.height, a.width, a.seq,
                a.time_base, a.encoding, a.is_bigendian) == (
            b.header.stamp.sec, b.header.stamp.nanosec, b.header.frame_id, b.height, b.width, b.seq,
            b.time_base, b.encoding, b.is_bigendian)
        assert bytes(a.events) == bytes(b.events)


def test_each_encoding_decodes_through_the_stream_decoder():
    payload = mono_payload([1, 2], [3, 4], [5, 6], [0, 1])
    ev = EventPacketDecoder().decode(packet_bytes('mono', payload, time_base=NS))[1]
    assert ev.t.tolist() == [NS + 1, NS + 2]
    payload = libcaer_payload([1, 2], [3, 4], [5, 6], [0, 1])
    ev = EventPacketDecoder().decode(packet_bytes('libcaer', payload, time_base=NS))[1]
    assert ev.t.tolist() == [NS + 1000, NS + 2000]
    assert EventPacketDecoder().decode(packet_bytes('trigger', bytes(8), time_base=NS))[1].t.size == 0


@pytest.mark.parametrize(('fields', 'match'), [
    ({'encoding': 'evt2'}, "encoding 'evt2' is not one of"),
    ({'encoding': 'mono', 'is_bigendian': True}, 'is_bigendian set'),
])
def test_unknown_encoding_and_big_endian_flag_are_clear_errors(fields, match):
    raw = packet_bytes(payload=bytes(8), **fields)
    with pytest.raises(MessageError, match=match):
        EventPacketDecoder().decode(raw)
    with pytest.raises(MessageError, match=match):
        restamp_event_packet(raw, ClockCorrection(offset_ns=1))


def test_stream_anomalies_seq_gaps_backward_time_and_a_changed_encoding():
    dec = EventPacketDecoder()
    one = mono_payload([0], [0], [0], [0])
    dec.decode(packet_bytes('mono', one, time_base=10 * NS, seq=1))
    dec.decode(packet_bytes('mono', one, time_base=9 * NS, seq=4))   # 2 missing, time back
    dec.decode(packet_bytes('mono', one, time_base=11 * NS, seq=4))  # duplicate seq
    assert dec.anomalies == {'messages missing (seq gap)': 2, 'time going backwards between messages': 1,
                             'seq not increasing (duplicate, reordered or restarted)': 1}
    with pytest.raises(MessageError, match='changed from mono'):
        dec.decode(packet_bytes('libcaer', b'', seq=5))


def test_evt3_clock_jump_re_anchors_and_is_counted():
    words = lambda th, tl: np.array([(0x8 << 12) | th, (0x6 << 12) | tl, 0x2 << 12], '<u2').tobytes()
    dec = EventPacketDecoder()
    _, ev = dec.decode(packet_bytes('evt3', words(100, 0), stamp_ns=50 * NS, seq=1))
    assert ev.t.tolist() == [50 * NS]
    # the camera restarts: sensor time back near zero, host time moves on by 10 ms
    _, ev = dec.decode(packet_bytes('evt3', words(0, 1), stamp_ns=50 * NS + 10_000_000, seq=2))
    assert ev.t.tolist() == [50 * NS + 10_000_000]
    assert dec.anomalies['sensor clock jump (re-anchored to header.stamp)'] == 1


@pytest.mark.parametrize(('encoding', 'payload'), [
    ('libcaer', libcaer_payload([0, 3, 1_000_000], [1, 2, 3], [4, 5, 6], [0, 1, 0])),
    ('mono', mono_payload([0, 3, 1_000_000], [1, 2, 3], [4, 5, 6], [0, 1, 0])),
    ('libcaer_cmp', np.array([0x0001, 0x1005, 0x2003, 0x3004, 0x4806, 0x5005], '<u2').tobytes()),
    ('trigger', mono_payload([5], [0], [0], [1])),
])
@pytest.mark.parametrize('d', [1, -999_999_999, 7 * 86_400 * NS])
def test_every_encoding_round_trips_by_d_then_minus_d(encoding, payload, d):
    # the stamp is time_base's here, as restamping makes it: the round trip gives back every byte
    raw = packet_bytes(encoding, payload, time_base=1_700_000_000 * NS, stamp_ns=1_700_000_000 * NS)
    t = EventPacketDecoder().decode(raw)[1].t
    moved = restamp_event_packet(raw, ClockCorrection(offset_ns=d))
    np.testing.assert_array_equal(EventPacketDecoder().decode(moved)[1].t, t + d)
    assert bytes(restamp_event_packet(moved, ClockCorrection(offset_ns=-d))) == raw


@pytest.mark.parametrize('frame_id', ['', 'a', 'camera_01'])
@pytest.mark.parametrize('encoding', ['evt3', 'mono'])
def test_packet_encoder_writes_what_rosbags_writes(frame_id, encoding):
    from msg_adapters.event_packet import encode_event_packet
    payload = bytes(range(37))
    ours = encode_event_packet(stamp_ns=5 * NS + 7, frame_id=frame_id, width=640, height=480, seq=3,
                               time_base=11, encoding=encoding, payload=payload)
    assert ours == packet_bytes(encoding, payload, time_base=11, stamp_ns=5 * NS + 7, seq=3, frame_id=frame_id)


# -- live streams: a correction that changes between messages reaches a consumer that anchors once --

from msg_adapters.event_packet import EventPacketStreamRestamper, encode_event_packet  # noqa: E402
from msg_adapters.evt3 import encode_evt3  # noqa: E402


def _evt3_stream(seconds=40, seed=4, start_ns=1_700_000_000 * NS):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, seconds * 1_000_000, 60_000))  # us of sensor time: two 24-bit wraps
    x, y, p = rng.integers(0, 64, t.size), rng.integers(0, 48, t.size), rng.integers(0, 2, t.size)
    cuts = np.searchsorted(t, np.arange(0, seconds * 1_000_000, 50_000))
    msgs = []
    for k, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
        if b > a:  # header.stamp: host time of the message's first event, with 0-2 ms of latency
            stamp = start_ns + int(t[a]) * 1000 + int(rng.integers(0, 2_000_000))
            msgs.append(encode_event_packet(stamp_ns=stamp, frame_id='cam', width=64, height=48, seq=k,
                                            time_base=0, encoding='evt3',
                                            payload=encode_evt3(t[a:b], x[a:b], y[a:b], p[a:b])))
    return msgs


@pytest.mark.parametrize('plan', ['constant', 'lock after forwarding', 'updates and skew', 'lock seconds away'])
def test_live_evt3_restamp_reaches_a_decoder_that_anchors_once(plan):
    msgs = _evt3_stream()
    n = len(msgs)

    def correction(k):
        if plan == 'constant':
            return ClockCorrection(offset_ns=2_500_000)
        if plan == 'lock after forwarding':
            return ClockCorrection(offset_ns=0 if k < n // 4 else -3_456_000)
        if plan == 'updates and skew':
            return ClockCorrection(offset_ns=7_000_000 + 3_000 * (k // 50), skew_ppm=40.0 if k > n // 2 else 0.0,
                                   anchor_ns=1_700_000_020 * NS)
        return ClockCorrection(offset_ns=0 if k < n // 3 else -1_000 * NS - 123_000)

    restamper = EventPacketStreamRestamper()
    source, consumer = EventPacketDecoder(), EventPacketDecoder()
    unchanged = 0
    for k, raw in enumerate(msgs):
        c = correction(k)
        out = restamper.restamp(raw, c)
        unchanged += bytes(out[-len(parse_event_packet(raw).events):]) == bytes(parse_event_packet(raw).events)
        _, before = source.decode(raw, xyp=True)
        view, after = consumer.decode(out, xyp=True)
        assert view.stamp_ns == after.t[0]  # the one stamp rule: the first event's time
        joining = EventPacketDecoder().decode(out)[1].t  # a consumer that starts at this message
        np.testing.assert_array_equal(joining, after.t)
        np.testing.assert_allclose(after.t, c.apply(before.t), atol=1000)  # to the microsecond
        np.testing.assert_array_equal(after.x, before.x)
        np.testing.assert_array_equal(after.p, before.p)
    if plan == 'constant':
        assert unchanged == n  # nothing to carry in the payload: copied as it is
    elif plan == 'lock seconds away':
        assert consumer.anomalies.get('sensor clock jump (re-anchored to header.stamp)') == 1
    elif plan == 'lock after forwarding':  # the lock moves the stream 3.456 ms back: once, and seen
        assert consumer.anomalies == {'time going backwards between messages': 1, 'small backward time step': 1}
    else:
        assert not consumer.anomalies


def _ros1_store():
    """The types a ROS 1 bag's reader builds (the ROS 2 Header, then the bag's own), with EventPacket."""
    from rosbags.typesys import get_types_from_msg

    from evsync_ros.bag.ros1 import typestore_for
    from msg_adapters.definitions import MSG_DEFINITIONS
    store = typestore_for([])
    types = get_types_from_msg(MSG_DEFINITIONS[EVENT_PACKET], EVENT_PACKET)
    types.pop('std_msgs/msg/Header', None)
    store.register(types)
    return store


@pytest.mark.parametrize('frame_id', ['', 'a', 'ab', 'abc', 'cam0', 'é', 'event_camera'])
@pytest.mark.parametrize('encoding', ['', 'e', 'evt3', 'trigger', 'libcaer_cmp'])
@pytest.mark.parametrize('n', [0, 1, 3, 1000])
def test_ros1_conversion_of_a_packet_is_rosbags_own_byte_for_byte(frame_id, encoding, n):
    from msg_adapters.event_packet import event_packet_from_ros1, event_packet_to_ros1
    store = _ros1_store()
    cdr = encode_event_packet(stamp_ns=1_700_000_000 * NS + 5, frame_id=frame_id, width=1280, height=720,
                              seq=2**40 + 3, time_base=7 * NS, encoding=encoding, payload=bytes(range(256))[:n] * 4)
    theirs = bytes(store.cdr_to_ros1(cdr, EVENT_PACKET))  # rosbags' generated converter
    assert event_packet_to_ros1(cdr) == theirs
    assert event_packet_from_ros1(theirs) == bytes(store.ros1_to_cdr(theirs, EVENT_PACKET)) == cdr
    assert event_packet_to_ros1(cdr, seq=42)[:4] == (42).to_bytes(4, 'little')


def test_ros1_conversion_of_a_packet_leaves_what_it_does_not_know_to_rosbags():
    from msg_adapters.event_packet import event_packet_from_ros1, event_packet_to_ros1
    store = _ros1_store()
    cdr = encode_event_packet(stamp_ns=NS, frame_id='cam', width=1, height=1, seq=1, time_base=0, encoding='evt3',
                              payload=b'\x01\x02\x03\x04')
    ros1 = bytes(store.cdr_to_ros1(cdr, EVENT_PACKET))
    assert event_packet_from_ros1(ros1[:-1]) is None  # truncated
    assert event_packet_from_ros1(ros1 + b'\x00') is None  # a byte past its events
    flag = bytearray(ros1)
    flag[-9] = 2  # is_bigendian, a bool, neither 0 nor 1
    assert event_packet_from_ros1(bytes(flag)) is None
    assert event_packet_to_ros1(cdr[:-1]) is None
    assert event_packet_to_ros1(cdr + b'\x00') is None
