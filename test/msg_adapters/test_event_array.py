"""dvs and prophesee EventArray: fixed-stride reads and in-place restamps agree with rosbags and rclpy."""

from typing import Any

import numpy as np
import pytest

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.errors import MessageError
from evsync_testing.messages import NS, array_bytes
from msg_adapters.definitions import DVS_EVENT_ARRAY, PROPHESEE_EVENT_ARRAY, event_typestore
from msg_adapters.event_array import EventArrayDecoder, parse_event_array, restamp_event_array

TYPES = [DVS_EVENT_ARRAY, PROPHESEE_EVENT_ARRAY]
T0 = 1_700_000_000 * NS


def _times(n, seed=0):
    rng = np.random.default_rng(seed)
    return T0 + np.cumsum(rng.integers(0, 3 * NS // max(n, 1), n))  # crosses whole seconds


@pytest.mark.parametrize('msgtype', TYPES)
@pytest.mark.parametrize('n', [0, 1, 2, 3, 257])
@pytest.mark.parametrize('frame_id', ['', 'a', 'ab', 'abc'])  # every alignment of the sequence
def test_decode_agrees_with_rosbags(msgtype, n, frame_id):
    t = _times(n)
    rng = np.random.default_rng(n)
    x, y, p = rng.integers(0, 346, n), rng.integers(0, 260, n), rng.integers(0, 2, n)
    raw = array_bytes(msgtype, t, x, y, p, frame_id=frame_id, stamp_ns=T0 + 5)
    view, ev = EventArrayDecoder(what=msgtype).decode(raw, xyp=True)
    msg: Any = event_typestore().deserialize_cdr(raw, msgtype)
    assert (view.stamp_ns, view.frame_id, view.width, view.height, view.count) == (T0 + 5, frame_id, 346, 260, n)
    assert ev.t.tolist() == [e.ts.sec * NS + e.ts.nanosec for e in msg.events] == t.tolist()
    assert ev.x.tolist() == [e.x for e in msg.events]
    assert ev.y.tolist() == [e.y for e in msg.events]
    assert ev.p.tolist() == [int(e.polarity) for e in msg.events]


@pytest.mark.parametrize('msgtype', TYPES)
@pytest.mark.parametrize('d', [1, -1, 999_999_999, -2_500_000_001, 123_456_789_012])
def test_restamp_by_d_then_minus_d_gives_back_the_same_bytes(msgtype, d):
    raw = array_bytes(msgtype, _times(300, seed=d % 7), frame_id='davis')
    there = restamp_event_array(raw, ClockCorrection(offset_ns=d), what=msgtype)
    view, ev = EventArrayDecoder().decode(there)
    assert ev.t.tolist() == (_times(300, seed=d % 7) + d).tolist()
    assert view.stamp_ns == parse_event_array(raw).stamp_ns + d
    back = restamp_event_array(there, ClockCorrection(offset_ns=-d), what=msgtype)
    assert bytes(back) == raw


def test_restamp_applies_skew_about_its_anchor():
    t = _times(50)
    raw = array_bytes(DVS_EVENT_ARRAY, t)
    c = ClockCorrection(offset_ns=-7_000, skew_ppm=120.0, anchor_ns=int(t[0]))
    _, ev = EventArrayDecoder().decode(restamp_event_array(raw, c))
    np.testing.assert_array_equal(ev.t, c.apply(t))


@pytest.mark.parametrize('msgtype', TYPES)
def test_rosbags_and_rclpy_read_a_restamped_message_identically(msgtype):
    serialization = pytest.importorskip('rclpy.serialization', reason='rclpy is installed by ./dev setup')
    module = __import__(msgtype.split('/')[0] + '.msg', fromlist=['EventArray'])
    t = _times(40)
    raw = restamp_event_array(array_bytes(msgtype, t, frame_id='x'), ClockCorrection(offset_ns=-1_234_567_891))
    a: Any = event_typestore().deserialize_cdr(bytes(raw), msgtype)
    b = serialization.deserialize_message(bytes(raw), module.EventArray)
    assert (a.header.stamp.sec, a.header.stamp.nanosec, a.header.frame_id) == (
        b.header.stamp.sec, b.header.stamp.nanosec, b.header.frame_id)
    assert [(e.x, e.y, e.ts.sec, e.ts.nanosec, e.polarity) for e in a.events] == [
        (e.x, e.y, e.ts.sec, e.ts.nanosec, e.polarity) for e in b.events]
    assert [e.ts.sec * NS + e.ts.nanosec for e in a.events] == (t - 1_234_567_891).tolist()


def test_every_truncation_is_a_clear_error():
    raw = array_bytes(DVS_EVENT_ARRAY, _times(3), frame_id='cam')
    for cut in range(len(raw)):
        with pytest.raises(MessageError, match='EventArray'):
            EventArrayDecoder(what=DVS_EVENT_ARRAY).decode(raw[:cut])


def test_restamp_outside_builtin_time_is_refused():
    raw = array_bytes(DVS_EVENT_ARRAY, _times(3))
    with pytest.raises(MessageError, match='builtin_interfaces/Time'):
        restamp_event_array(raw, ClockCorrection(offset_ns=-(T0 + 3 * NS) - (1 << 31) * NS + NS // 2))


def test_odd_times_are_counted():
    t = _times(5)
    t[3] = t[1] - 10  # backwards
    raw = bytearray(array_bytes(DVS_EVENT_ARRAY, t))
    view = parse_event_array(raw)
    raw[view.first + 16 * 4 + 8: view.first + 16 * 4 + 12] = (2 * NS).to_bytes(4, 'little')  # nanosec >= 1e9
    dec = EventArrayDecoder()
    _, ev = dec.decode(raw)
    assert ev.t.size == 5
    assert dec.anomalies == {'time going backwards within a message': 1, 'ts.nanosec of 1e9 or more': 1}


@pytest.mark.parametrize('n', [0, 1, 2, 50])
@pytest.mark.parametrize('frame_id', ['', 'ab', 'abc'])
def test_encoder_writes_what_rosbags_writes(n, frame_id):
    from msg_adapters.event_array import encode_event_array
    t = _times(n)
    rng = np.random.default_rng(n)
    x, y, p = rng.integers(0, 346, n), rng.integers(0, 260, n), rng.integers(0, 2, n)
    ours = encode_event_array(stamp_ns=T0 + 9, frame_id=frame_id, width=346, height=260, t=t, x=x, y=y, p=p)
    assert ours == array_bytes(DVS_EVENT_ARRAY, t, x, y, p, stamp_ns=T0 + 9, frame_id=frame_id)


@pytest.mark.parametrize('n', [0, 1, 2, 7, 1000])
@pytest.mark.parametrize('frame_id', ['', 'a', 'davis_left'])
def test_ros1_conversion_is_rosbags_own_byte_for_byte(n, frame_id):
    from rosbags.typesys import get_types_from_msg

    from evsync_ros.bag.ros1 import typestore_for
    from msg_adapters.definitions import DVS_EVENT_ARRAY, MSG_DEFINITIONS
    from msg_adapters.event_array import encode_event_array, event_array_from_ros1, event_array_to_ros1
    rng = np.random.default_rng(n)
    t = np.sort(rng.integers(1_700_000_000 * 10**9, 1_700_000_010 * 10**9, n))
    cdr = encode_event_array(stamp_ns=1_700_000_000 * 10**9 + 5, frame_id=frame_id, width=346, height=260, t=t,
                             x=rng.integers(0, 346, n), y=rng.integers(0, 260, n), p=rng.integers(0, 2, n))
    store = typestore_for([])  # the types a ROS 1 bag's reader builds: the ROS 2 Header, then the bag's own
    types = {}
    for name in ('dvs_msgs/msg/Event', DVS_EVENT_ARRAY):
        types.update(get_types_from_msg(MSG_DEFINITIONS[name], name))
    types.pop('std_msgs/msg/Header', None)
    store.register(types)
    theirs = bytes(store.cdr_to_ros1(cdr, DVS_EVENT_ARRAY))  # rosbags' converter, a Python step per event
    assert event_array_to_ros1(cdr, seq=0) == theirs
    assert event_array_from_ros1(theirs) == bytes(store.ros1_to_cdr(theirs, DVS_EVENT_ARRAY)) == cdr
    assert event_array_to_ros1(cdr, seq=42)[:4] == (42).to_bytes(4, 'little')
