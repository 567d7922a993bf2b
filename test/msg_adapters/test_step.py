"""A live message in one C call (``EventPacketDecoder.step``, ``EventArrayDecoder.step``) gives what the
separate calls give: the same event times, anomalies and lost messages, the same restamped bytes or
error, its events' counts on the grid as numpy counts them, and state carried so that every later
message is the same too; on every event message of the real recordings, each encoding, under corrections
that change from message to message, and for bytes it does not take (nothing moved)."""

from __future__ import annotations

import numpy as np
import pytest

from evsync_ros.bag.reader import BagReader
from evsync_ros.core.clock import ClockCorrection
from evsync_testing.messages import (
    ONE_EVENT,
    evt3_packets,
    libcaer_payload,
    mono_payload,
    odd_evt3_packets,
    packet_bytes,
    rewritten,
)
from msg_adapters.cdr import MAX_TIME_NS
from msg_adapters.definitions import EVENT_PACKET
from msg_adapters.errors import MessageError
from msg_adapters.event_packet import parse_event_packet
from msg_adapters.registry import Restamper, decoder_for, is_event_type

NS = 1_000_000_000
GRID = 100_000
CORRECTIONS = [
    None,  # decoded and counted, not restamped (a camera held before its lock)
    ClockCorrection(offset_ns=12_345_678),
    ClockCorrection(offset_ns=-2_000_000, skew_ppm=80.0, anchor_ns=1_700_000_000 * NS),
    ClockCorrection(offset_ns=3 * NS),  # past the re-anchoring distance: the output anchor moves
]


def streams(path) -> dict[str, tuple[str, list[bytes]]]:
    with BagReader(path) as reader:
        out: dict[str, tuple[str, list[bytes]]] = {}
        for conn, _, raw in reader.messages():
            if is_event_type(conn.msgtype):
                out.setdefault(conn.topic, (conn.msgtype, []))[1].append(raw)
    return out


def apart(msgtype, messages, corrections, edges=False):
    """Each message through ``decode_times`` (``decode_times_edges`` with ``edges``) and
    ``Restamper.restamp``: (times or error, bytes or error, edges or None)."""
    decoder, restamper = decoder_for(msgtype), Restamper(msgtype)
    return [_decode(decoder, raw, i == 0, edges) + (_restamp(restamper, raw, c),)
            for i, (raw, c) in enumerate(zip(messages, corrections))], decoder


def _decode(decoder, raw, first, edges):
    """(times or error, edges or None) as the separate calls give them."""
    try:
        if first:
            _, events, found = decoder.decode_edges(raw) if edges else (None, decoder.decode(raw)[1], None)
            return events.t.copy(), found
        if edges:
            times, found = decoder.decode_times_edges(raw)
            return times.copy(), found
        return decoder.decode_times(raw).copy(), None
    except MessageError as exc:
        return str(exc), None


def _restamp(restamper, raw, c):
    if c is None:
        return None
    try:
        return bytes(restamper.restamp(raw, c))
    except MessageError as exc:
        return str(exc)


def in_one_call(msgtype, messages, corrections, edges=False):
    """The same messages through ``step`` (the first decoded, the stream's, as the node does): (times, bytes
    or error, edges or None) and how many the one call took."""
    decoder, restamper = decoder_for(msgtype), Restamper(msgtype)
    counts = np.zeros(4096, np.int32)
    out, taken = [], 0
    for i, (raw, c) in enumerate(zip(messages, corrections)):
        step = None if i == 0 else decoder.step(raw, grid_ns=GRID, counts=counts, restamper=restamper.packets,
                                                correction=c, edges=edges)
        if step is None:
            out.append(_decode(decoder, raw, i == 0, edges) + (_restamp(restamper, raw, c),))
            continue
        taken += 1
        times = step.times.copy()
        if times.size:
            assert (step.lo, step.hi, step.mid) == (times.min(), times.max(), times[times.size // 2])
            dense = np.bincount(times // GRID - times.min() // GRID)
            assert step.k0 == times.min() // GRID
            if dense.size > counts.size:  # spanning more bins than the counts hold: none given
                assert step.counts is None
            else:
                assert step.counts is not None and np.array_equal(step.counts, dense)
        else:
            assert step.counts is None
        got = None if c is None else bytes(step.out) if step.out is not None else step.error
        out.append((times, step.edges, got))
    return out, decoder, taken


def same_both_ways(msgtype, messages, corrections, edges=False):
    """(messages the one call took, edges it gave)."""
    theirs, d1 = apart(msgtype, messages, corrections, edges)
    ours, d2, taken = in_one_call(msgtype, messages, corrections, edges)
    assert len(ours) == len(theirs)
    n_edges = 0
    for i, ((t1, e1, b1), (t2, e2, b2)) in enumerate(zip(theirs, ours)):
        assert t1 == t2 if isinstance(t1, str) else np.array_equal(t1, t2), f'message {i}: times'
        assert b1 == b2, f'message {i}: restamped'
        assert (e1 is None) == (e2 is None) == (not edges), f'message {i}: edges asked'
        if edges:
            assert all(np.array_equal(getattr(e1, f), getattr(e2, f)) for f in ('t', 'value', 'channel')), \
                f'message {i}: edges'
            n_edges += len(e2)
    assert dict(d1.anomalies) == dict(d2.anomalies)
    assert getattr(d1, 'lost', 0) == getattr(d2, 'lost', 0)
    return taken, n_edges


@pytest.mark.parametrize('edges', [False, True])
@pytest.mark.parametrize('name', ['evt3_sqlite3', 'evt3_trigger', 'evk4_hd', 'dvs128_stereo/fan',
                                  'libcaer_cmp_mcap'])
def test_real_recordings_the_same_in_one_call(real_data, name, edges):
    """Times, restamped bytes, anomalies and (asked for, as a stream with ``trigger_channels``) trigger
    edges: the one call gives what the separate calls give."""
    taken = n_edges = 0
    for msgtype, messages in streams(real_data / name).values():
        messages = messages[:3000]
        corrections = [CORRECTIONS[(i // 7) % len(CORRECTIONS)] for i in range(len(messages))]
        took, found = same_both_ways(msgtype, messages, corrections, edges)
        taken, n_edges = taken + took, n_edges + found
    assert taken > 0
    if edges and name.startswith('evt3_'):
        assert n_edges > 0  # the recordings' EXT_TRIGGER words


def test_odd_packets_are_left_to_the_separate_calls_with_nothing_moved():
    """Packets the one call does not take (cut, big-endian, a time_base, odd bytes, another encoding ...)
    among plain ones, under changing corrections: the stream is the same as through the separate calls."""
    good = evt3_packets(12)
    cases = [*odd_evt3_packets(good), packet_bytes('evt3', ONE_EVENT, seq=15, stamp_ns=1_900_000_000 * NS),
             packet_bytes('evt3', ONE_EVENT, seq=16, width=320)]  # a sensor clock jump; another geometry
    messages = [*good[:4], *cases, *good[4:]]
    corrections = [CORRECTIONS[i % len(CORRECTIONS)] for i in range(len(messages))]
    assert same_both_ways(EVENT_PACKET, messages, corrections)[0] >= len(good) - 1


def test_a_libcaer_cmp_stream_restamped_throughout_takes_the_one_call_after_its_first_message(real_data):
    """Its restamper keeps up with the stream's decoder (the message is not decoded again to restamp
    it); one that misses messages (a camera restamped apart meanwhile) sends the next apart, as above."""
    for msgtype, messages in streams(real_data / 'libcaer_cmp_mcap').values():
        corrections = [CORRECTIONS[1 + (i // 7) % (len(CORRECTIONS) - 1)] for i in range(len(messages))]
        taken, _ = same_both_ways(msgtype, messages, corrections)
        assert taken == len(messages) - 1


def test_odd_libcaer_cmp_packets_are_left_to_the_separate_calls_with_nothing_moved(real_data):
    """libcaer_cmp packets the one call does not take (cut, big-endian, odd bytes, a time_base past any ROS
    time, another geometry or encoding, a restamped time_base leaving uint64) among the recording's own:
    the stream is the same as through the separate calls."""
    (msgtype, messages), *_ = streams(real_data / 'libcaer_cmp_mcap').values()
    payload = parse_event_packet(messages[3]).events.tobytes()
    def cmp(seq: int, *, encoding: str = 'libcaer_cmp', tail: bytes = b'', time_base: int = 1_744_227_145 * NS,
            width: int = 346, is_bigendian: bool = False, empty: bool = False) -> bytes:
        return packet_bytes(encoding, b'' if empty else payload + tail, seq=seq, time_base=time_base, width=width,
                            height=260, is_bigendian=is_bigendian)
    cases = [messages[5][:-3], messages[5][:40], b'\x01\x00' + messages[5][2:], cmp(900, tail=b'\x01'),
             cmp(901, is_bigendian=True), cmp(902, time_base=MAX_TIME_NS + 1), cmp(903, width=320),
             cmp(904, encoding='libcaer'), cmp(905, time_base=1),  # moved below 0 by the correction below
             cmp(906, empty=True)]
    stream = [*messages[:6], *cases, *messages[6:20]]
    corrections = [CORRECTIONS[1 + i % (len(CORRECTIONS) - 1)] for i in range(len(stream))]
    corrections[6 + len(cases) - 2] = CORRECTIONS[2]  # -2 ms: the time_base of 1 ns cannot move
    taken, _ = same_both_ways(msgtype, stream, corrections)
    assert taken >= 19 - 2  # the recording's own but the first, and one or two after a message apart


@pytest.mark.parametrize('encoding', ['libcaer', 'mono'])
def test_libcaer_and_mono_streams_take_the_one_call_as_libcaer_cmp_does(real_data, encoding):
    """The real DAVIS346 recording written as libcaer and as mono: every message after the first in one
    call, restamped throughout or held (no correction) now and then, the same as the separate calls."""
    messages = rewritten(streams(real_data / 'libcaer_cmp_mcap').popitem()[1][1], encoding)
    restamped = [CORRECTIONS[1 + (i // 7) % (len(CORRECTIONS) - 1)] for i in range(len(messages))]
    assert same_both_ways(EVENT_PACKET, messages, restamped)[0] == len(messages) - 1
    mixed = [CORRECTIONS[(i // 7) % len(CORRECTIONS)] for i in range(len(messages))]
    assert same_both_ways(EVENT_PACKET, messages, mixed)[0] > len(messages) // 2


def test_odd_libcaer_and_mono_packets_are_counted_as_the_separate_calls_count_them():
    """libcaer: negative timestamps, small steps back, an overflow inside a message, one missing from
    time_base (carried from there); mono: dt going backwards; and packets the one call does not take
    (trailing bytes, big-endian, a time_base past any ROS time, another geometry, empty): the same times,
    bytes and anomalies as the separate calls give."""
    base = 1_744_227_145 * NS
    top = (1 << 31) - 1000

    def libcaer(seq: int, ts: list[int], **kw) -> bytes:
        return packet_bytes('libcaer', libcaer_payload(ts, range(len(ts)), range(len(ts)), [1] * len(ts))
                            + kw.pop('tail', b''), seq=seq, time_base=kw.pop('time_base', base), **kw)

    half_us = 1 << 30
    negative = bytearray(libcaer_payload([5, 6], [1, 2], [1, 2], [0, 1]))
    negative[15] |= 0x80  # the last event's timestamp with bit 31 set
    stream = [libcaer(1, [10, 20, 30]), libcaer(2, [40, 35, 50]),
              libcaer(3, [top, top + 500, 20, 60]),  # an overflow inside: the stream's last time is 2^31 + 60 us
              libcaer(4, [half_us]),  # over 2^30 us before that last time (not before the message's first): carried
              packet_bytes('libcaer', bytes(negative), seq=5, time_base=base),
              libcaer(6, [half_us + 100, 100]),  # a step back of exactly 2^30 us: backwards, not an overflow
              libcaer(7, [100], time_base=base - half_us * 1000),  # exactly 2^30 us before the last time: kept
              libcaer(8, [90], tail=b'\x01\x02'), libcaer(9, [95], is_bigendian=True),
              libcaer(10, [96], time_base=MAX_TIME_NS + 1), libcaer(11, [97], width=320), libcaer(12, []),
              libcaer(13, [100, 110]), libcaer(14, [5, 6], time_base=1),  # moved below 0 by its correction
              libcaer(15, [5, 6], time_base=base - 2000 * NS),  # 2^31 us carried
              libcaer(16, [120, 130])]
    corrections = [CORRECTIONS[1 + i % (len(CORRECTIONS) - 1)] for i in range(len(stream))]
    corrections[13] = CORRECTIONS[2]  # -2 ms: the time_base of 1 ns cannot move
    taken, _ = same_both_ways(EVENT_PACKET, stream, corrections)
    assert taken >= 10
    counted = in_one_call(EVENT_PACKET, stream, corrections)[1].anomalies
    assert {'negative libcaer timestamp', 'time going backwards within a message',
            '31-bit overflow missing from time_base (carried)'} <= set(counted), counted
    mono = [([10, 20], b'', base), ([30, 25, 40], b'', base), ([50], b'\x07', base), ([], b'', base),
            ([60, 70], b'', 1), ([80], b'', base)]
    dt = [packet_bytes('mono', mono_payload(d, [1] * len(d), [1] * len(d), [0] * len(d)) + tail, seq=i, time_base=tb)
          for i, (d, tail, tb) in enumerate(mono)]
    assert same_both_ways(EVENT_PACKET, dt, [CORRECTIONS[1]] * 4 + [CORRECTIONS[2], CORRECTIONS[1]])[0] >= 3
