"""``decode_times``, the estimate's decode (a plain evt3 packet in one C call), against ``decode``:
message for message the same times or the same error, and the same stream state after it."""

from __future__ import annotations

import numpy as np
import pytest

from evsync_ros.bag.reader import BagReader
from evsync_testing.messages import ONE_EVENT, array_bytes, odd_evt3_packets, packet_bytes
from evsync_testing.messages import evt3_packets as packets
from msg_adapters import _kernels
from msg_adapters.definitions import DVS_EVENT_ARRAY, EVENT_PACKET
from msg_adapters.errors import MessageError
from msg_adapters.event_array import event_array_from_ros1, event_array_to_ros1
from msg_adapters.event_packet import event_packet_from_ros1, event_packet_to_ros1
from msg_adapters.evt3 import encode_evt3
from msg_adapters.registry import decoder_for, is_event_type

NS = 1_000_000_000


def state(decoder) -> tuple:
    """What a decoder carries from message to message, as comparable values."""
    codec = getattr(decoder, '_codec', None)
    return (list(decoder.anomalies.items()), getattr(decoder, 'lost', 0), getattr(decoder, 'anchor_ns', None),
            getattr(decoder, '_last_seq', None), getattr(decoder, '_last_t', None),
            None if codec is None else getattr(codec, '_state', np.zeros(0)).tolist())


def same_both_ways(msgtype: str, messages: list[bytes], monkeypatch) -> int:
    """Each message through ``decode`` on one decoder and ``decode_times`` on another: equal times or
    errors, equal states after each; returns how many the C call took."""
    taken = [0]

    def counted(kernel):
        def call(*args):
            out = kernel(*args)
            taken[0] += out is not None
            return out
        return call

    for name in ('evt3_packet_decode', 'event_array_times'):
        monkeypatch.setattr(_kernels, name, counted(getattr(_kernels, name)))
    theirs, ours = decoder_for(msgtype), decoder_for(msgtype)
    for i, raw in enumerate(messages):
        try:
            expected: np.ndarray | str = theirs.decode(raw)[1].t
        except MessageError as exc:
            expected = str(exc)
        try:
            got: np.ndarray | str = ours.decode_times(raw)
        except MessageError as exc:
            got = str(exc)
        if isinstance(expected, str):
            assert got == expected, i
        else:
            assert isinstance(got, np.ndarray) and got.dtype == np.int64, i
            np.testing.assert_array_equal(got, expected, err_msg=f'message {i}')
        assert state(ours) == state(theirs), i
    return taken[0]


@pytest.mark.parametrize('name', ['evt3_sqlite3', 'libcaer_cmp_mcap', 'dvs128_stereo/fan'])
def test_real_recordings_decode_the_same(real_data, monkeypatch, name):
    with BagReader(real_data / name) as reader:
        streams: dict[str, tuple[str, list[bytes]]] = {}
        for conn, _, raw in reader.messages():
            if is_event_type(conn.msgtype):
                streams.setdefault(conn.topic, (conn.msgtype, []))[1].append(raw)
    taken = sum(same_both_ways(msgtype, messages, monkeypatch) for msgtype, messages in streams.values())
    if name == 'libcaer_cmp_mcap':
        assert taken == 0  # libcaer_cmp goes through decode
    else:  # evt3 packets, every one after its stream's first (which sets the stream's geometry); arrays
        assert taken == sum(len(m) - (t == EVENT_PACKET) for t, m in streams.values()) > 500


def test_evt3_edge_cases_decode_the_same(monkeypatch):
    good = packets(8)
    one = ONE_EVENT
    cases = [
        *odd_evt3_packets(good),
        packet_bytes('evt3', one, seq=15, width=1280),  # the geometry changes mid-stream
        packet_bytes('evt3', one, seq=15, height=720),
        packet_bytes('evt3', one, seq=15),  # seq not increasing
        packet_bytes('evt3', one, seq=40),  # a seq gap
        packet_bytes('evt3', one, seq=41, stamp_ns=1_900_000_000 * NS),  # a sensor clock jump: re-anchored
        packet_bytes('evt3', one, seq=42, frame_id=''),
        packet_bytes('evt3', bytes.fromhex('00d0') + one, seq=43),  # an unknown word type
        packet_bytes('evt3', encode_evt3(np.array([6_000]), np.array([900]), np.array([1]), np.array([1])),
                     seq=44),  # an event outside the geometry, and time going backwards
    ]
    messages = [*good[:3], *cases, *good[3:]]
    assert same_both_ways(EVENT_PACKET, messages, monkeypatch) >= len(good)
    # a stream whose first messages have no event (nothing anchored yet), then one that starts with
    # an odd geometry
    empty = [packet_bytes('evt3', b'', seq=i) for i in range(2)]
    assert same_both_ways(EVENT_PACKET, empty + good, monkeypatch) >= len(good)
    assert same_both_ways(EVENT_PACKET, packets(5, width=1280, height=720), monkeypatch) == 4


def test_evt3_sensor_time_wraps_decode_the_same(monkeypatch):
    """Packets across evt3's 2^24 us wrap of its time words: the wrap count carries in the state."""
    start = (1 << 24) - 3_500
    assert same_both_ways(EVENT_PACKET, packets(8, start_us=start), monkeypatch) == 7


def event_arrays() -> list[bytes]:
    """EventArrays and what can be wrong with them."""
    t0 = 1_700_000_000 * NS
    good = [array_bytes(DVS_EVENT_ARRAY, [t0 + k * 1000 + j for j in range(3)]) for k in range(4)]
    odd = [
        good[0][:-5],  # truncated
        b'\x01\x00' + good[1][2:],  # big-endian CDR
        good[1][:14],
        array_bytes(DVS_EVENT_ARRAY, []),  # no events
        array_bytes(DVS_EVENT_ARRAY, [t0 + 5, t0 + 2, t0 + 9, t0 + 1]),  # backwards within
        array_bytes(DVS_EVENT_ARRAY, [t0], frame_id=''),
        array_bytes(DVS_EVENT_ARRAY, [-5 * NS + 3, (1 << 31) * NS - 1]),  # the int32 seconds' ends
    ]
    nsec = bytearray(good[2])  # an event's nanosec of 1e9 or more
    first = len(nsec) - 16 * 3 + 3
    nsec[first + 8:first + 12] = (1_500_000_000).to_bytes(4, 'little')
    return [*good[:2], *odd, bytes(nsec), *good[2:]]


def test_event_arrays_decode_the_same(monkeypatch):
    messages = event_arrays()
    assert same_both_ways(DVS_EVENT_ARRAY, messages, monkeypatch) == len(messages) - 3


def test_ros1_event_arrays_decode_as_their_conversion():
    messages = [event_array_to_ros1(m) for m in event_arrays() if _converts(m)]
    messages += [messages[0][:-1], messages[1] + b'\x00', messages[2][:27]]
    theirs, ours = decoder_for(DVS_EVENT_ARRAY), decoder_for(DVS_EVENT_ARRAY)
    taken = 0
    for i, raw in enumerate(messages):
        direct = ours.decode_ros1_times(raw)
        taken += direct is not None
        try:
            expected: np.ndarray | str = theirs.decode_times(event_array_from_ros1(raw))
        except MessageError as exc:
            expected = str(exc)
        if direct is None:
            assert isinstance(expected, str), i  # left to the conversion, which refuses it
        else:
            np.testing.assert_array_equal(direct, expected, err_msg=f'message {i}')
        assert state(ours) == state(theirs), i
    assert taken == len(messages) - 3


def _converts(cdr: bytes) -> bool:
    try:
        event_array_to_ros1(cdr)
    except MessageError:
        return False
    return True


def test_ros1_packets_decode_as_their_conversion(monkeypatch):
    """``decode_ros1_times`` on a ROS 1 EventPacket as it is gives what converting it
    (``event_packet_from_ros1``) and ``decode_times`` give; None, nothing moved, where it leaves the
    message to be converted."""
    one = encode_evt3(np.array([7_000]), np.array([1]), np.array([1]), np.array([1]))
    cdrs = [*packets(4), packet_bytes('evt3', one, seq=9, width=1280), packet_bytes('evt3', one + b'\x01', seq=10),
            packet_bytes('evt3', one, seq=11, time_base=NS), packet_bytes('evt3', one, seq=12, is_bigendian=True),
            packet_bytes('evt2', one, seq=13), packet_bytes('evt3', one, seq=3), *packets(3, start_us=(1 << 24) - 1500,
                                                                                       seq0=14)]
    messages = [event_packet_to_ros1(c, seq=i) for i, c in enumerate(cdrs)]
    messages += [messages[1][:-2], messages[2] + b'\x00', messages[3][:20]]  # lengths that do not add up
    taken = 0
    for start in range(2):  # from a stream's first message, and from its second
        theirs, ours = decoder_for(EVENT_PACKET), decoder_for(EVENT_PACKET)
        for i, raw in enumerate(messages[start:]):
            cdr = event_packet_from_ros1(raw)
            direct = ours.decode_ros1_times(raw)
            taken += direct is not None
            assert direct is None or cdr is not None, i
            outcomes = []
            for decoder, got in ((theirs, None), (ours, direct)):
                try:
                    outcomes.append(got if got is not None else 'not a packet' if cdr is None
                                    else decoder.decode_times(cdr))
                except MessageError as exc:
                    outcomes.append(str(exc))
            if isinstance(outcomes[0], str):
                assert outcomes[1] == outcomes[0], i
            else:
                np.testing.assert_array_equal(outcomes[1], outcomes[0], err_msg=f'message {i}')
            assert state(ours) == state(theirs), i
    assert taken >= 10
