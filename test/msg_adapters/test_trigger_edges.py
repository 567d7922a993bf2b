"""Trigger edges (evt3 EXT_TRIGGER words, the ``trigger`` encoding): the real recordings' edges
against an independent word-by-word decoder, the per-message paths against each other, and what
cannot be placed counted."""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from evsync_ros.bag.reader import BagReader
from evsync_ros.core.clock import ClockCorrection
from evsync_testing.messages import array_bytes, evt3_packets, odd_evt3_packets, packet_bytes
from evsync_testing.realdata import missing
from evsync_testing.reference import evt3_reference_edges, trigger_reference_edges
from msg_adapters.definitions import DVS_EVENT_ARRAY, EVENT_PACKET, event_typestore
from msg_adapters.edges import TriggerEdges
from msg_adapters.errors import MessageError
from msg_adapters.event_packet import UNANCHORED_EDGE, EventPacketDecoder, parse_event_packet
from msg_adapters.evt3 import Evt3Decoder, encode_evt3
from msg_adapters.registry import Restamper, decoder_for, stream_edges
from msg_adapters.trigger import encode_trigger

NS = 1_000_000_000
EARLY = "trigger edge before the stream's first time (not emitted)"


@pytest.fixture(scope='module')
def trigger_bag(real_data: Path) -> Path:
    """evt3_trigger, which the session's set of recordings does not name."""
    reason = missing(real_data, 'evt3_trigger')
    if reason:
        if os.environ.get('CI'):
            pytest.fail(reason)
        pytest.skip(reason)
    return real_data / 'evt3_trigger'


def messages(bag: Path) -> list[bytes]:
    with BagReader(bag) as reader:
        return [bytes(raw) for _, _, raw in reader.messages()]


def reference(raws: list[bytes]) -> np.ndarray:
    """The independent decoder's edges, (t, value, channel) rows, from rosbags' deserialization."""
    store = event_typestore()
    msgs: list[Any] = [store.deserialize_cdr(raw, EVENT_PACKET) for raw in raws]
    rows = evt3_reference_edges([(m.header.stamp.sec * NS + m.header.stamp.nanosec, m.events.tobytes())
                                 for m in msgs], msgs[0].width, msgs[0].height)
    return np.array(rows, np.int64).reshape(-1, 3)


def rows(edges: TriggerEdges) -> np.ndarray:
    return np.stack([edges.t, edges.value.astype(np.int64), edges.channel.astype(np.int64)], axis=1)


def test_evt3_trigger_two_edges_on_channel_0(trigger_bag):
    raws = messages(trigger_bag)
    got = stream_edges(raws, EVENT_PACKET)
    assert (got.messages, got.undecodable, dict(got.anomalies)) == (105, 0, {})
    decoder = EventPacketDecoder()
    for raw in raws:
        decoder.decode(raw)
    assert decoder.anchor_ns is not None
    edges = got.edges
    assert edges.value.tolist() == [0, 1] and edges.channel.tolist() == [0, 0]
    assert (edges.t - decoder.anchor_ns).tolist() == [14_547_491_000, 14_549_491_000]  # sensor time, as documented
    np.testing.assert_array_equal(rows(edges), reference(raws))


def test_evt3_sqlite3_4157_alternating_edges_on_channel_6(real_data):
    raws = messages(real_data / 'evt3_sqlite3')
    got = stream_edges(raws, EVENT_PACKET)
    edges = got.edges
    assert (len(edges), got.undecodable, dict(got.anomalies)) == (4157, 0, {})
    assert set(edges.channel.tolist()) == {6}
    assert np.all(edges.value[1:] != edges.value[:-1])
    assert np.all(np.diff(edges.t) == 500_000)
    np.testing.assert_array_equal(rows(edges), reference(raws))


def test_no_edges_in_a_recording_without_trigger_words(real_data):
    with BagReader(real_data / 'evk4_hd') as reader:
        got = stream_edges((raw for _, _, raw in reader.messages()), EVENT_PACKET)
    assert (len(got.edges), got.messages, dict(got.anomalies)) == (0, 10768, {})


def state(decoder: EventPacketDecoder) -> tuple:
    codec = decoder._codec
    return (dict(decoder.anomalies), decoder.anchor_ns, decoder._last_seq, decoder._last_t,
            None if codec is None else getattr(codec, '_state', np.zeros(0)).tolist())


def same_every_way(raws: list[bytes]) -> TriggerEdges:
    """``decode_edges`` (and with x, y, polarity), ``decode_times_edges`` and ``decode`` on four
    decoders: the same events or error per message, the same edges, the same state after each."""
    plain, with_xyp, quick, events_only = (EventPacketDecoder() for _ in range(4))
    parts = []
    for i, raw in enumerate(raws):
        try:
            expected = events_only.decode(raw)[1].t
        except MessageError as exc:
            for decoder in (plain, with_xyp, quick):
                with pytest.raises(MessageError, match=re.escape(str(exc))):
                    decoder.decode_edges(raw)
            continue
        _, events, edges = plain.decode_edges(raw)
        _, events_xyp, edges_xyp = with_xyp.decode_edges(raw, xyp=True)
        times, edges_quick = quick.decode_times_edges(raw)
        for t in (events.t, events_xyp.t, times):
            np.testing.assert_array_equal(t, expected, err_msg=f'message {i}')
        for other in (edges_xyp, edges_quick):
            np.testing.assert_array_equal(rows(other), rows(edges), err_msg=f'message {i}')
        parts.append(edges)
        assert state(plain) == state(with_xyp) == state(quick), i
        assert state(events_only)[1:] == state(plain)[1:], i  # anomalies: edges are counted only when asked for
    return TriggerEdges.concatenate(parts)


def test_every_path_the_same_on_the_real_edges(real_data, trigger_bag):
    for bag in (trigger_bag, real_data / 'evt3_sqlite3'):
        raws = messages(bag)
        np.testing.assert_array_equal(rows(same_every_way(raws)), reference(raws))


def test_state_carries_across_messages_wherever_they_are_cut(real_data):
    payload = np.concatenate([parse_event_packet(raw).events for raw in messages(real_data / 'evt3_sqlite3')])
    whole_events, whole = Evt3Decoder(width=640, height=480).decode_edges(payload)
    assert len(whole) == 4157
    cuts = np.sort(np.random.default_rng(3).choice(np.arange(1, payload.size // 2), 400, replace=False)) * 2
    decoder = Evt3Decoder(width=640, height=480)
    pieces = [decoder.decode_edges(part) for part in np.split(payload, cuts)]
    np.testing.assert_array_equal(rows(TriggerEdges.concatenate([p[1] for p in pieces])), rows(whole))
    np.testing.assert_array_equal(np.concatenate([p[0].t for p in pieces]), whole_events.t)


def crafted(n: int, *, edges_at_us: list[int], start_us: int = 5_000, seq0: int = 0) -> list[bytes]:
    """n evt3 packets of four events 1 ms apart (as ``evt3_packets``), edges (alternating values,
    channel 3) among them."""
    out = []
    edge_t = np.array(edges_at_us)
    for i in range(n):
        t = start_us + 1000 * i + np.arange(4) * 100
        mine = edge_t[(edge_t >= t[0]) & (edge_t < t[0] + 1000)]
        words = encode_evt3(t, np.arange(4) * 200, np.arange(4) * 150, np.ones(4),
                            edges=(mine, np.searchsorted(edge_t, mine) % 2, np.full(mine.size, 3)))
        stamp = 1_700_000_000 * NS + 1000 * (int(t[0]) - start_us)
        out.append(packet_bytes('evt3', words, seq=seq0 + i, stamp_ns=stamp))
    return out


def test_crafted_edges_land_on_the_events_timeline():
    raws = crafted(6, edges_at_us=[5_050, 6_999, 7_000, 9_250])
    edges = same_every_way(raws)
    anchor = 1_700_000_000 * NS - 5_000_000
    assert ((edges.t - anchor) // 1000).tolist() == [5_050, 6_999, 7_000, 9_250]
    assert edges.value.tolist() == [0, 1, 0, 1] and edges.channel.tolist() == [3] * 4
    np.testing.assert_array_equal(rows(edges), reference(raws))


def test_every_path_the_same_on_odd_packets():
    good = crafted(8, edges_at_us=[5_100, 7_300, 9_900, 11_050])
    with_edge = encode_evt3(np.array([7_000]), np.array([1]), np.array([1]), np.array([1]),
                            edges=(np.array([7_000]), np.array([1]), np.array([2])))
    odd = [*odd_evt3_packets(good), packet_bytes('evt3', with_edge, seq=20, time_base=5 * NS),
           packet_bytes('evt3', with_edge + b'\x01', seq=21), packet_bytes('evt3', with_edge, seq=22, width=1280)]
    edges = same_every_way([*good[:3], *odd, *good[3:]])
    assert len(edges) == 4 + 2  # the crafted ones, the one after a time_base, the one before an odd byte


def test_edges_that_cannot_be_placed_are_counted():
    # an EXT_TRIGGER before any time word, and one in a message of time words and edges only, before
    # the stream's first event: neither has a place on the timeline
    ext = (0xA << 12) | (2 << 8) | 1
    no_time = packet_bytes('evt3', np.array([ext], '<u2').tobytes(), seq=0)
    no_event = packet_bytes('evt3', np.array([0x8000, 0x6010, ext, ext], '<u2').tobytes(), seq=1)
    raws = [no_time, no_event, *crafted(2, edges_at_us=[5_500], seq0=2)]
    edges = same_every_way(raws)
    assert len(edges) == 1
    decoder = EventPacketDecoder()
    for raw in raws:
        decoder.decode_edges(raw)
    assert dict(decoder.anomalies) == {EARLY: 1, UNANCHORED_EDGE: 2}
    assert reference(raws).shape == (1, 3)


def test_edges_of_a_packet_with_a_time_base_are_relative_to_it():
    words = encode_evt3(np.array([100]), np.array([1]), np.array([1]), np.array([1]),
                        edges=(np.array([250]), np.array([1]), np.array([9])))
    raw = packet_bytes('evt3', words, time_base=5 * NS)
    _, events, edges = EventPacketDecoder().decode_edges(raw)
    assert (events.t.tolist(), edges.t.tolist()) == ([5 * NS + 100_000], [5 * NS + 250_000])
    assert edges.channel.tolist() == [9]


def test_trigger_encoding_edges():
    dt = np.array([0, 1_000, 250_000_000])
    payload = encode_trigger(dt, np.array([1, 0, 1]), np.array([0, 7, 0x7FFF]))
    raws = [packet_bytes('trigger', payload, time_base=3 * NS, seq=1, width=1, height=1),
            packet_bytes('trigger', payload[:8] + b'\x01\x02', time_base=4 * NS, seq=2, width=1, height=1)]
    edges = same_every_way(raws)
    assert edges.t.tolist() == [3 * NS, 3 * NS + 1_000, 3 * NS + 250_000_000, 4 * NS]
    assert edges.value.tolist() == [1, 0, 1, 1] and edges.channel.tolist() == [0, 7, 0x7FFF, 0]
    expected = trigger_reference_edges([(3 * NS, payload), (4 * NS, payload[:8] + b'\x01\x02')])
    np.testing.assert_array_equal(rows(edges), np.array(expected))
    got = stream_edges(raws, EVENT_PACKET)
    assert dict(got.anomalies) == {'trailing bytes (not a whole trigger)': 2}  # counted once, not per path
    backwards = packet_bytes('trigger', encode_trigger(np.array([5, 4]), np.zeros(2), np.zeros(2)), width=1, height=1)
    assert dict(stream_edges([backwards], EVENT_PACKET).anomalies) == {'time going backwards within a message': 1}
    with pytest.raises(ValueError, match='2\\^32'):
        encode_trigger(np.array([1 << 32]), np.zeros(1), np.zeros(1))


def test_types_without_edges_give_none():
    raws = [array_bytes(DVS_EVENT_ARRAY, [NS, NS + 5])]
    decoder = decoder_for(DVS_EVENT_ARRAY)
    _, events, edges = decoder.decode_edges(raws[0])
    assert (len(events), len(edges)) == (2, 0)
    assert len(decoder.decode_times_edges(raws[0])[1]) == 0
    assert len(stream_edges(evt3_packets(3), EVENT_PACKET).edges) == 0


def test_stream_edges_counts_what_it_cannot_read():
    raws = crafted(3, edges_at_us=[6_100])
    got = stream_edges([raws[0], b'\x00\x01\x00\x00 not a packet', raws[1], raws[2]], EVENT_PACKET)
    assert (len(got.edges), got.messages, got.undecodable) == (1, 4, 1)
    assert got.first_error is not None and 'EventPacket' in got.first_error


def test_a_restamped_trigger_stream_is_stamped_at_its_first_edge():
    raw = packet_bytes('trigger', encode_trigger([1_000, 9_000], [1, 0], [0, 0]), time_base=3 * NS,
                       stamp_ns=3 * NS + 12_000_000, width=1, height=1)
    out = Restamper(EVENT_PACKET).restamp(raw, ClockCorrection(offset_ns=-NS))
    _, _, edges = decoder_for(EVENT_PACKET).decode_edges(bytes(out))
    assert edges.t.tolist() == [2 * NS + 1_000, 2 * NS + 9_000]
    assert parse_event_packet(bytes(out)).stamp_ns == 2 * NS + 1_000


def test_restamping_moves_evt3_edges_with_the_events():
    raws = crafted(40, edges_at_us=[5_200 + 997 * k for k in range(35)])
    correction = ClockCorrection(offset_ns=-3 * NS + 123_456, skew_ppm=80.0, anchor_ns=1_700_000_000 * NS)
    restamper = Restamper(EVENT_PACKET)
    moved = [bytes(restamper.restamp(raw, correction)) for raw in raws]
    before, after = stream_edges(raws, EVENT_PACKET).edges, stream_edges(moved, EVENT_PACKET).edges
    assert len(before) == len(after) == 35
    np.testing.assert_array_equal(after.value, before.value)
    error = after.t - correction.apply(before.t)
    assert np.abs(error).max() <= 1_000  # the time words' microseconds
    assert np.any(correction.apply(before.t) - correction.apply(before.t[:1]) != before.t - before.t[0])  # skewed
