"""libcaer_cmp: the C word loop against a plain word-by-word reference decoder, on the real DAVIS recording."""

import numpy as np
import pytest

from evsync_ros.bag.reader import BagReader
from evsync_testing.reference import libcaer_cmp_reference_decode
from msg_adapters.event_packet import parse_event_packet
from msg_adapters.libcaer_cmp import LibcaerCmpDecoder


@pytest.fixture(scope='module')
def cmp_packets(real_data):
    with BagReader(real_data / 'libcaer_cmp_mcap') as reader:
        return [parse_event_packet(raw) for _, _, raw in reader.messages()]


def test_known_answer_on_the_real_davis_recording(cmp_packets):
    p = cmp_packets[0]
    assert (p.encoding, p.width, p.height) == ('libcaer_cmp', 346, 260)
    packets = [(bytes(q.events), q.time_base) for q in cmp_packets]
    ref = np.array(libcaer_cmp_reference_decode(packets, 346, 260), dtype=np.int64)
    dec = LibcaerCmpDecoder(width=346, height=260)
    parts = [dec.decode(q.events, time_base=q.time_base, xyp=True) for q in cmp_packets]
    got = np.stack([np.concatenate([getattr(e, f) for e in parts]).astype(np.int64) for f in 'txyp'], axis=1)
    assert got.shape == ref.shape == (571_266, 4)  # both decoders agree on every event
    np.testing.assert_array_equal(got, ref)
    assert dec.anomalies == {}
    t = got[:, 0]
    assert np.all(np.diff(t) >= 0)
    # every message's events start at its time_base and span its ~10 ms
    assert all(e.t[0] == q.time_base and e.t[-1] - e.t[0] < 20_000_000 for e, q in zip(parts, cmp_packets))


def _words(*pairs):
    return np.array([(code << 12) | v for code, v in pairs], dtype='<u2').view(np.uint8)


def test_vectors_geometry_and_unsupported_words():
    dec = LibcaerCmpDecoder(width=10, height=10)
    payload = _words((0, 1), (1, 5), (2, 3), (3, 4 | 1 << 11),      # t = 4101 us: (3, 4, on)
                     (4, 6), (5, 0b101),                          # y 6 and 8 at x 3, off
                     (2, 12), (3, 1),                             # x outside the sensor
                     (6, 0xFFF), (0xB, 0))                        # VECT_12 and an unknown code
    ev = dec.decode(payload, time_base=1_000, xyp=True)
    assert ev.t.tolist() == [4101 * 1000 + 1000] * 3
    assert list(zip(ev.x.tolist(), ev.y.tolist(), ev.p.tolist())) == [(3, 4, 1), (3, 6, 0), (3, 8, 0)]
    assert dec.anomalies == {'event outside the sensor geometry': 1, 'VECT_12 word (not decoded)': 1,
                             'unknown word type': 1}


def test_time_restarts_per_message_but_coordinates_carry():
    dec = LibcaerCmpDecoder(width=10, height=10)
    dec.decode(_words((1, 7), (2, 5)), time_base=0)
    ev = dec.decode(_words((3, 2)), time_base=50_000, xyp=True)  # x 5 from the message before, time 0
    assert (ev.t.tolist(), ev.x.tolist(), ev.y.tolist()) == ([50_000], [5], [2])


def test_odd_byte_count_is_counted():
    dec = LibcaerCmpDecoder(width=10, height=10)
    ev = dec.decode(np.concatenate([_words((3, 1)), np.array([7], np.uint8)]), time_base=0)
    assert ev.t.size == 1 and dec.anomalies == {'odd byte count': 1}
