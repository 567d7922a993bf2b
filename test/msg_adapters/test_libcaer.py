"""libcaer (8 bytes per event): known answers, the 31-bit overflow in a message and across messages."""

import numpy as np

from evsync_testing.messages import libcaer_payload
from msg_adapters.libcaer import LibcaerDecoder

BASE = 1_700_000_000_000_000_000


def test_fields_and_times_known_answer():
    ts = [0, 5, 5, 1_000_000]
    payload = libcaer_payload(ts, x=[1, 345, 0, 7], y=[2, 259, 0, 8], p=[1, 0, 1, 0])
    ev = LibcaerDecoder().decode(payload, time_base=BASE, xyp=True)
    assert ev.t.tolist() == [BASE + v * 1000 for v in ts]
    assert (ev.x.tolist(), ev.y.tolist(), ev.p.tolist()) == ([1, 345, 0, 7], [2, 259, 0, 8], [1, 0, 1, 0])


def test_overflow_inside_a_message_carries_to_its_end():
    top = (1 << 31) - 2
    ev = LibcaerDecoder().decode(libcaer_payload([top, top + 1, 3, 4], [0] * 4, [0] * 4, [0] * 4), time_base=BASE)
    assert ev.t.tolist() == [BASE + top * 1000, BASE + (top + 1) * 1000,
                             BASE + ((1 << 31) + 3) * 1000, BASE + ((1 << 31) + 4) * 1000]
    assert np.all(np.diff(ev.t) > 0)


def test_overflow_missing_from_time_base_is_carried_and_counted():
    dec = LibcaerDecoder()
    top = (1 << 31) - 10
    dec.decode(libcaer_payload([top], [0], [0], [0]), time_base=BASE)
    ev = dec.decode(libcaer_payload([2], [0], [0], [0]), time_base=BASE)  # driver did not bump time_base
    assert ev.t.tolist() == [BASE + ((1 << 31) + 2) * 1000]
    assert dec.anomalies == {'31-bit overflow missing from time_base (carried)': 1}


def test_bad_input_is_counted_not_fatal():
    dec = LibcaerDecoder()
    payload = libcaer_payload([10, 9, -5], [0] * 3, [0] * 3, [0] * 3) + b'\x01\x02\x03'
    ev = dec.decode(payload, time_base=0)
    assert ev.t.tolist() == [10_000, 9_000, ((1 << 31) - 5) * 1000]
    assert dec.anomalies == {'trailing bytes (not a whole libcaer event)': 3, 'negative libcaer timestamp': 1,
                             'time going backwards within a message': 1}
    assert dec.decode(b'', time_base=0).t.size == 0
