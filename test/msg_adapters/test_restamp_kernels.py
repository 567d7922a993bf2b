"""Restamping a whole message in one C call (``_kernels.evt3_packet_restamp``, ``_kernels.event_array_restamp``)
gives what the Python path gives, byte for byte, error for error, and the state it leaves behind makes the
next message the same too: every event message of the real recordings, under an offset, no correction, a
skew, and edge cases made by hand (malformed, out of range, re-anchoring, no events)."""

from __future__ import annotations

import numpy as np
import pytest

from evsync_ros.bag.reader import BagReader
from evsync_ros.core.clock import ClockCorrection
from evsync_testing.messages import ONE_EVENT, array_bytes, odd_evt3_packets, packet_bytes
from msg_adapters import _kernels
from msg_adapters.cdr import write_stamp
from msg_adapters.definitions import DVS_EVENT_ARRAY, EVENT_PACKET
from msg_adapters.errors import MessageError
from msg_adapters.event_array import event_array_from_ros1, event_array_to_ros1
from msg_adapters.event_packet import event_packet_from_ros1, event_packet_to_ros1
from msg_adapters.evt3 import encode_evt3
from msg_adapters.registry import Restamper, is_event_type

NS = 1_000_000_000
CORRECTIONS = [
    ClockCorrection(offset_ns=12_345_678),
    ClockCorrection(),
    ClockCorrection(offset_ns=-2_000_000, skew_ppm=80.0, anchor_ns=1_700_000_000 * NS),
    ClockCorrection(offset_ns=37_400_000, skew_ppm=-60.0, anchor_ns=NS),
    ClockCorrection(offset_ns=3 * NS),  # past REANCHOR_NS: the output anchor moves
]


def restamped(msgtype, messages, corrections, monkeypatch, *, kernel):
    """Each message restamped in stream order by one Restamper (the C calls, or with ``kernel`` False
    the Python path alone): its bytes or its error, and how many the C calls took."""
    taken = [0]
    packet, array = _kernels.evt3_packet_restamp, _kernels.event_array_restamp

    def counted(fn):
        def call(*args):
            out = fn(*args) if kernel else None
            taken[0] += out is not None
            return out
        return call

    with monkeypatch.context() as m:
        m.setattr(_kernels, 'evt3_packet_restamp', counted(packet))
        m.setattr(_kernels, 'event_array_restamp', counted(array))
        r = Restamper(msgtype)
        out: list[bytes | str] = []
        for raw, corr in zip(messages, corrections):
            try:
                out.append(bytes(r.restamp(raw, corr)))
            except MessageError as exc:
                out.append(str(exc))
    return out, taken[0]


def same_both_ways(msgtype, messages, corrections, monkeypatch):
    """The C calls' outputs equal the Python path's; returns how many messages the C calls took."""
    ours, taken = restamped(msgtype, messages, corrections, monkeypatch, kernel=True)
    theirs, none = restamped(msgtype, messages, corrections, monkeypatch, kernel=False)
    assert none == 0
    assert ours == theirs
    return taken


@pytest.mark.parametrize('corr', CORRECTIONS, ids=lambda c: f'{c.offset_ns}/{c.skew_ppm}')
@pytest.mark.parametrize('name', ['evt3_sqlite3', 'libcaer_cmp_mcap', 'dvs128_stereo/fan'])
def test_real_recordings_restamp_the_same(real_data, monkeypatch, name, corr):
    with BagReader(real_data / name) as reader:
        streams: dict[str, tuple[str, list[bytes]]] = {}
        for conn, _, raw in reader.messages():
            if is_event_type(conn.msgtype):
                streams.setdefault(conn.topic, (conn.msgtype, []))[1].append(raw)
    taken = 0
    for msgtype, messages in streams.values():
        taken += same_both_ways(msgtype, messages, [corr] * len(messages), monkeypatch)
    if name != 'libcaer_cmp_mcap':  # libcaer_cmp keeps to the Python path: its time_base moves
        assert taken > 0


@pytest.mark.parametrize('name', ['evt3_sqlite3', 'evt3_trigger'])
def test_real_evt3_restamps_the_same_under_a_moving_correction(real_data, monkeypatch, name):
    """A correction that moves from message to message, as the node's does once locked: the time words
    move, and the C call writes the whole packet around them (``retimed_packet``)."""
    with BagReader(real_data / name) as reader:
        messages = [raw for conn, _, raw in reader.messages() if conn.msgtype == EVENT_PACKET][:400]
    track = [ClockCorrection(offset_ns=5_000_000 + 700 * i, skew_ppm=12.0, anchor_ns=NS) for i in range(len(messages))]
    assert same_both_ways(EVENT_PACKET, messages, track, monkeypatch) == len(messages)


def evt3_stream(n=6, *, start_us=5_000, stamp_ns=1_700_000_000 * NS):
    """n evt3 packets of a few events each, stamped at their first event's time."""
    out = []
    for i in range(n):
        t = start_us + 1000 * i + np.arange(4) * 100
        out.append(packet_bytes('evt3', encode_evt3(t, np.arange(4), np.arange(4), np.ones(4)), seq=i,
                                stamp_ns=stamp_ns + 1000 * (int(t[0]) - start_us)))
    return out


def test_evt3_edge_cases_restamp_the_same(monkeypatch):
    good = evt3_stream(8)
    ff = ONE_EVENT
    cases = [
        *odd_evt3_packets(good),
        packet_bytes('evt3', ff, seq=15, stamp_ns=(1 << 31) * NS - 1),  # the stamp leaves int32 seconds
        packet_bytes('evt3', ff, seq=16, stamp_ns=1_900_000_000 * NS),  # a sensor clock jump: re-anchored
        packet_bytes('evt3', ff, seq=17, frame_id=''),
    ]
    messages = [*good[:3], *cases, *good[3:]]
    for corr in CORRECTIONS + [ClockCorrection(offset_ns=-1_700_000_000 * NS - 1)]:
        taken = same_both_ways(EVENT_PACKET, messages, [corr] * len(messages), monkeypatch)
        assert taken >= len(good)
    # a correction that changes from message to message (a track): the time words move
    changing = [ClockCorrection(offset_ns=1000 * i, skew_ppm=float(i)) for i in range(len(messages))]
    assert same_both_ways(EVENT_PACKET, messages, changing, monkeypatch) >= len(good)
    # a stream whose first messages have no event: nothing anchored yet
    empty = [packet_bytes('evt3', b'', seq=i) for i in range(2)]
    assert same_both_ways(EVENT_PACKET, empty + good, [CORRECTIONS[0]] * 10, monkeypatch) == 10


@pytest.mark.parametrize('corr', [
    ClockCorrection(offset_ns=1_000_001, skew_ppm=62_500.0, anchor_ns=1_700_000_000 * NS + 1),  # k = 1/16: halves
    ClockCorrection(offset_ns=-999, skew_ppm=-62_500.0, anchor_ns=1_700_000_000 * NS - 3),
    ClockCorrection(offset_ns=7, skew_ppm=2_000.0),  # k (t - anchor) past 2^51 ns: libm's rounding
    ClockCorrection(offset_ns=7, skew_ppm=-2_000.0, anchor_ns=-NS),
], ids=['ties', 'ties-negative', 'past-2^51', 'past-2^51-negative'])
def test_the_skew_rounds_as_python_does(monkeypatch, corr):
    """The C calls round the skew's share of a time, k (t - anchor), to nearest, ties to even, as Python's
    ``round`` does, whether it is small (rounded without libm) or past 2^51 (libm's ``nearbyint``): an
    event array's nanosecond times show every rounding; evt3's microsecond time words share it."""
    t = 1_700_000_000 * NS + np.arange(400) * 1_000_003  # t - anchor through every residue mod 16
    arrays = [array_bytes(DVS_EVENT_ARRAY, t[i:i + 100]) for i in range(0, 400, 100)]
    assert same_both_ways(DVS_EVENT_ARRAY, arrays, [corr] * len(arrays), monkeypatch) == len(arrays)
    packets = evt3_stream(8, start_us=5_001)
    assert same_both_ways(EVENT_PACKET, packets, [corr] * len(packets), monkeypatch) == len(packets)


def test_event_array_edge_cases_restamp_the_same(monkeypatch):
    t = 1_700_000_000 * NS + np.arange(5) * 1_000_000
    good = array_bytes(DVS_EVENT_ARRAY, t)
    big_nsec = bytearray(good)
    first = len(good) - 16 * 5 + 3
    big_nsec[first + 8:first + 12] = (NS + 5).to_bytes(4, 'little')  # ts.nanosec of 1e9 or more
    cases = [
        good,
        array_bytes(DVS_EVENT_ARRAY, []),  # no events: the stamp corrected
        array_bytes(DVS_EVENT_ARRAY, [], stamp_ns=(1 << 31) * NS - 1),  # the stamp leaves int32 seconds
        array_bytes(DVS_EVENT_ARRAY, [(1 << 31) * NS - 2]),  # an event's time leaves int32 seconds
        bytes(big_nsec),
        good[:-1],  # truncated
        b'\x01\x00' + good[2:],  # big-endian
        good[:14],
        array_bytes('prophesee_event_msgs/msg/EventArray', t, frame_id=''),
    ]
    for corr in CORRECTIONS + [ClockCorrection(offset_ns=-1_700_000_000 * NS - 1)]:
        assert same_both_ways(DVS_EVENT_ARRAY, cases, [corr] * len(cases), monkeypatch) >= 2


def ros1_restamped(messages, corr, *, direct):
    """Each ROS 1 EventPacket restamped as ``bag.restamp`` does ROS 1 to ROS 1: as ROS 1 bytes directly
    where ``restamp_ros1`` takes it (with ``direct``), else converted to CDR, restamped and converted back
    ('general': for rosbags' converter)."""
    r = Restamper(EVENT_PACKET)
    out: list[bytes | str] = []
    for raw in messages:
        try:
            done = r.restamp_ros1(raw, corr) if direct else None
            if done is None:
                cdr = event_packet_from_ros1(raw)
                if cdr is None:
                    out.append('general')
                    continue
                back = event_packet_to_ros1(r.restamp(cdr, corr), seq=int.from_bytes(raw[:4], 'little'))
                done = bytearray(back) if back is not None else None
            out.append(bytes(done) if done is not None else 'general')
        except MessageError as exc:
            out.append(str(exc))
    return out


def test_ros1_packets_restamp_as_converted():
    good = [event_packet_to_ros1(m, seq=i) for i, m in enumerate(evt3_stream(8))]
    assert all(m is not None for m in good)
    ff = encode_evt3(np.array([7_000]), np.array([1]), np.array([1]), np.array([1]))
    odd = [event_packet_to_ros1(m, seq=3) for m in (
        packet_bytes('evt3', ff, time_base=5 * NS), packet_bytes('evt2', ff),
        packet_bytes('evt3', ff, is_bigendian=True),
        packet_bytes('evt3', ff, stamp_ns=(1 << 31) * NS - 1), packet_bytes('evt3', ff, stamp_ns=1_900_000_000 * NS),
        packet_bytes('evt3', ff, frame_id=''), packet_bytes('evt3', b''))]
    plain = event_packet_to_ros1(packet_bytes('evt3', ff), seq=3)
    assert plain is not None and all(m is not None for m in odd)
    flag = bytearray(plain)
    flag[-(len(ff) + 5)] = 2  # an is_bigendian byte that is no bool
    cases = [*good[:3], *odd, good[2][:30], good[2] + b'\x00', bytes(flag), *good[3:]]
    for corr in CORRECTIONS + [ClockCorrection(offset_ns=-1_700_000_000 * NS - 1)]:
        direct = ros1_restamped(cases, corr, direct=True)
        assert direct == ros1_restamped(cases, corr, direct=False)
        assert sum(isinstance(m, bytes) for m in direct) >= len(good)


def test_ros1_event_arrays_restamp_as_converted():
    t = 1_700_000_000 * NS + np.arange(5) * 1_000_000
    good = array_bytes(DVS_EVENT_ARRAY, t)
    big_nsec = bytearray(good)
    first = len(good) - 16 * 5 + 3
    big_nsec[first + 8:first + 12] = (NS + 5).to_bytes(4, 'little')
    cdr = [good, array_bytes(DVS_EVENT_ARRAY, []), array_bytes(DVS_EVENT_ARRAY, [], stamp_ns=(1 << 31) * NS - 1),
           array_bytes(DVS_EVENT_ARRAY, [(1 << 31) * NS - 2]), bytes(big_nsec),
           array_bytes(DVS_EVENT_ARRAY, t, frame_id='')]
    ros1 = [event_array_to_ros1(m, seq=7) for m in cdr]
    cases = [*ros1, ros1[0][:-1], ros1[0] + b'\x00', ros1[0][:20]]

    def restamped(corr, *, direct):
        r = Restamper(DVS_EVENT_ARRAY)
        out: list[bytes | str] = []
        for raw in cases:
            try:
                done = r.restamp_ros1(raw, corr) if direct else None
                if done is None:
                    back = r.restamp(event_array_from_ros1(raw, what=DVS_EVENT_ARRAY), corr)
                    done = bytearray(event_array_to_ros1(back, seq=7, what=DVS_EVENT_ARRAY))
                out.append(bytes(done))
            except MessageError as exc:
                out.append(str(exc))
        return out

    for corr in CORRECTIONS + [ClockCorrection(offset_ns=-1_700_000_000 * NS - 1)]:
        direct = restamped(corr, direct=True)
        assert direct == restamped(corr, direct=False)
        assert sum(isinstance(m, bytes) for m in direct) >= 2


def restamped_rows(msgtype, messages, corr):
    """The messages restamped as ``restamp._copy_chunks`` restamps a chunk of them: one buffer, the C
    path over its rows for as long as it takes them (``Restamper.restamp_rows``), ``restamp`` for
    each it leaves; each message's bytes or error, how many the C path took, and the state left."""
    gaps = [bytes(3 + i % 5) for i in range(len(messages))]  # the records' other fields, between messages
    chunk = b''.join(g + m for g, m in zip(gaps, messages))
    starts = np.cumsum([len(g) for g in gaps]) + np.concatenate([[0], np.cumsum([len(m) for m in messages])[:-1]])
    rows = np.zeros((len(messages), 4), np.int64)
    rows[:, 0], rows[:, 1] = starts, [len(m) for m in messages]
    stamps = np.full(len(messages), np.iinfo(np.int64).min)
    new: list[bytes | bytearray | None] = [None] * len(messages)
    r, taken, i = Restamper(msgtype), 0, 0
    out: list[bytes | str] = []
    while i < len(messages):
        j = r.restamp_rows(chunk, rows, i, corr, stamps=stamps, new=new)
        for k in range(i, j):
            if new[k] is None:
                copy = bytearray(messages[k])
                write_stamp(copy, int(stamps[k]), 'test')
                new[k] = copy
            out.append(bytes(new[k]))
        taken += j - i
        if j < len(messages):
            try:
                out.append(bytes(r.restamp(messages[j], corr)))
            except MessageError as exc:
                out.append(str(exc))
        i = j + 1
    return out, taken, r


def _state(r):
    return None if r._packets is None else (r._packets._retimer.state.tolist(), r._packets._anchors.tolist())


@pytest.mark.parametrize('corr', CORRECTIONS, ids=lambda c: f'{c.offset_ns}/{c.skew_ppm}')
@pytest.mark.parametrize('name', ['evt3_sqlite3', 'evk4_hd', 'dvs128_stereo/fan'])
def test_rows_of_a_chunk_restamp_as_each_message_does(real_data, monkeypatch, name, corr):
    """``Restamper.restamp_rows`` (a chunk's messages in one C call, evt3 or EventArray) gives each
    message what ``restamp`` gives it, error for error, and leaves the stream's state where it does;
    on the real recordings with every 40th message cut short."""
    with BagReader(real_data / name) as reader:
        streams: dict[str, tuple[str, list[bytes]]] = {}
        for conn, _, raw in reader.messages():
            if is_event_type(conn.msgtype):
                streams.setdefault(conn.topic, (conn.msgtype, []))[1].append(bytes(raw))
    for msgtype, messages in streams.values():
        messages = messages[:3000]
        messages = [m[: len(m) * 2 // 3] if i % 40 == 9 else m for i, m in enumerate(messages)]
        ours, taken, r = restamped_rows(msgtype, messages, corr)
        theirs = Restamper(msgtype)
        expected: list[bytes | str] = []
        for raw in messages:
            try:
                expected.append(bytes(theirs.restamp(raw, corr)))
            except MessageError as exc:
                expected.append(str(exc))
        assert ours == expected
        assert _state(r) == _state(theirs)
        assert taken > len(messages) / 2


@pytest.mark.parametrize('corr', CORRECTIONS, ids=lambda c: f'{c.offset_ns}/{c.skew_ppm}')
def test_rows_restamp_as_each_message_across_sensor_time_wraps(corr):
    """The same over 40 s of evt3 packets (a sensor's time wraps every 16.8 s), some of them
    starting with events before their first time words, some empty, and some whose bytes before
    the payload are not what encoding them writes (encapsulation options, a frame_id not ASCII, a
    byte other than NUL after the encoding),
    which the Python path re-encodes when their time words move."""
    rng = np.random.default_rng(5)
    messages = []
    for k in range(400):  # 100 ms packets of a few events each
        t = np.sort(rng.integers(k * 100_000, (k + 1) * 100_000, 30))
        payload = encode_evt3(t, rng.integers(0, 640, 30), rng.integers(0, 480, 30), rng.integers(0, 2, 30))
        if k % 17 == 3:
            payload = b''
        elif k % 13 == 5:  # a packet cut after its first time words: its events ride on the last packet's
            payload = payload[6:]
        raw = packet_bytes('evt3', payload, stamp_ns=1_700_000_000 * NS + int(t[0]) * 1000,
                           frame_id='cäm' if k % 31 == 6 else 'cam')
        raw = raw.replace(b'evt3\x00', b'evt3\x01', 1) if k % 37 == 8 else raw  # decoded as evt3, encoded with NUL
        messages.append(raw[:2] + b'\x00\x07' + raw[4:] if k % 29 == 4 else raw)
    ours, taken, r = restamped_rows(EVENT_PACKET, messages, corr)
    theirs = Restamper(EVENT_PACKET)
    assert ours == [bytes(theirs.restamp(raw, corr)) for raw in messages]
    assert _state(r) == _state(theirs) and int(r._packets._retimer.state[2]) >= 2  # two wraps at least
    assert taken > 0
