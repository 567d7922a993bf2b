"""evt3: the stateful C word loop against a plain word-by-word reference decoder."""

import numpy as np
import pytest

from evsync_ros.bag.reader import BagReader
from evsync_testing.reference import evt3_reference_decode
from msg_adapters.event_packet import parse_event_packet
from msg_adapters.evt3 import Evt3Decoder, Evt3Retimer, encode_evt3


@pytest.fixture(scope='module')
def evt3_packets(real_data):
    with BagReader(real_data / 'evt3_sqlite3') as reader:
        return [parse_event_packet(raw) for _, _, raw in reader.messages()]


def test_packet_fields_parse_straight_from_cdr(evt3_packets):
    p = evt3_packets[0]
    assert (p.encoding, p.width, p.height, p.seq, p.time_base, p.is_bigendian) == ('evt3', 640, 480, 5590, 0, False)
    assert p.stamp_ns > 1_600_000_000 * 10**9  # host ROS time


def test_known_answer_343474_events_decoded_statefully(evt3_packets):
    dec = Evt3Decoder(width=640, height=480)
    times = np.concatenate([dec.decode(p.events).t for p in evt3_packets])
    assert times.size == 343_474
    assert np.all(np.diff(times) >= 0)
    assert dec.anomalies == {}


def test_decoder_matches_the_reference_event_for_event(evt3_packets):
    ref = np.array(evt3_reference_decode([p.events for p in evt3_packets], 640, 480), dtype=np.int64)
    dec = Evt3Decoder(width=640, height=480)
    parts = [dec.decode(p.events, xyp=True) for p in evt3_packets]
    got = np.stack([np.concatenate([getattr(e, f) for e in parts]).astype(np.int64) for f in 'txyp'], axis=1)
    assert got.shape == ref.shape == (343_474, 4)
    np.testing.assert_array_equal(got, ref)


def test_state_carries_across_messages_wherever_they_are_cut(evt3_packets):
    payload = np.concatenate([p.events for p in evt3_packets[:40]])
    whole = Evt3Decoder(width=640, height=480).decode(payload, xyp=True)
    rng = np.random.default_rng(0)
    cuts = np.sort(rng.choice(np.arange(1, payload.size // 2), 60, replace=False)) * 2
    dec = Evt3Decoder(width=640, height=480)
    pieces = [dec.decode(part, xyp=True) for part in np.split(payload, cuts)]
    for f in 'txyp':
        np.testing.assert_array_equal(np.concatenate([getattr(e, f) for e in pieces]), getattr(whole, f))


def _words(*pairs):
    return np.array([(typ << 12) | v for typ, v in pairs], dtype='<u2').view(np.uint8)


def test_24_bit_wrap_in_mid_message_keeps_time_monotonic():
    payload = _words((0x8, 0xFFF), (0x6, 0xFFE), (0x0, 5), (0x2, 7),   # t = 0xFFFFFE us
                     (0x8, 0x000), (0x6, 0x001), (0x2, 8))              # wrapped: 2^24 + 1 us
    ev = Evt3Decoder(width=640, height=480).decode(payload)
    assert ev.t.tolist() == [0xFFFFFE * 1000, ((1 << 24) + 1) * 1000]


def test_small_backward_step_is_tolerated_and_counted_not_a_wrap():
    dec = Evt3Decoder(width=640, height=480)
    ev = dec.decode(_words((0x8, 100), (0x6, 0), (0x2, 1), (0x8, 95), (0x6, 0), (0x2, 2)))
    assert ev.t.tolist() == [(100 << 12) * 1000, (95 << 12) * 1000]
    assert dec.anomalies == {'small backward time step': 1}


def test_events_before_the_first_valid_time_are_dropped():
    ev = Evt3Decoder(width=640, height=480).decode(_words((0x0, 1), (0x2, 3), (0x8, 1), (0x2, 4), (0x6, 2), (0x2, 5)))
    assert ev.t.tolist() == [((1 << 12) | 2) * 1000]


def test_odd_byte_count_and_unknown_words_are_counted():
    dec = Evt3Decoder(width=640, height=480)
    payload = np.concatenate([_words((0x8, 1), (0x6, 2), (0xB, 0), (0x2, 3)), np.array([0x42], np.uint8)])
    ev = dec.decode(payload)
    assert ev.t.size == 1
    assert dec.anomalies == {'odd byte count': 1, 'unknown word type': 1}


def test_encoder_round_trips_through_the_decoder_across_a_wrap():
    rng = np.random.default_rng(3)
    t_us = np.sort(rng.integers((1 << 24) - 50_000, (1 << 24) + 50_000, 5_000))  # crosses the 24-bit wrap
    x, y, p = rng.integers(0, 640, t_us.size), rng.integers(0, 480, t_us.size), rng.integers(0, 2, t_us.size)
    from msg_adapters.evt3 import encode_evt3
    dec = Evt3Decoder(width=640, height=480)
    parts = [dec.decode(encode_evt3(t_us[i:i + 700], x[i:i + 700], y[i:i + 700], p[i:i + 700]), xyp=True)
             for i in range(0, t_us.size, 700)]
    got = {f: np.concatenate([getattr(e, f) for e in parts]) for f in 'txyp'}
    np.testing.assert_array_equal(got['t'], t_us * 1000)  # the decoder counts the wrap back in
    np.testing.assert_array_equal(got['x'], x)
    np.testing.assert_array_equal(got['y'], y)
    np.testing.assert_array_equal(got['p'], p)
    assert dec.anomalies == {}


@pytest.mark.parametrize('skew_ppm', [60.0, -45.0, 500.0])
def test_retimed_time_words_carry_a_skew_across_wraps_and_messages(skew_ppm):
    rng = np.random.default_rng(0)
    t = np.sort(rng.integers(0, 40_000_000, 100_000))  # 40 s of microseconds: two 24-bit wraps
    x, y, p = rng.integers(0, 64, t.size), rng.integers(0, 48, t.size), rng.integers(0, 2, t.size)
    cuts = np.searchsorted(t, np.arange(0, 40_000_000, 7_000))
    payloads = [encode_evt3(t[a:b], x[a:b], y[a:b], p[a:b]) for a, b in zip(cuts[:-1], cuts[1:]) if b > a]
    retimer = Evt3Retimer(skew_ppm)
    plain, moved = Evt3Decoder(width=64, height=48), Evt3Decoder(width=64, height=48)
    before = [plain.decode(pl, xyp=True) for pl in payloads]
    after = [moved.decode(retimer.retime(pl), xyp=True) for pl in payloads]
    t0, t1 = np.concatenate([e.t for e in before]), np.concatenate([e.t for e in after])
    expected = t0 + np.rint(skew_ppm * 1e-6 * (t0 - t0[0]) / 1000) * 1000
    np.testing.assert_array_equal(t1, expected)
    for name in ('x', 'y', 'p'):
        np.testing.assert_array_equal(np.concatenate([getattr(e, name) for e in before]),
                                      np.concatenate([getattr(e, name) for e in after]))
    assert not moved.anomalies and abs(t1[-1] - t0[-1]) > 1_000_000 * abs(skew_ppm) / 60
