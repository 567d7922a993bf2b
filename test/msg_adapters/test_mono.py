"""mono (deprecated, 8 bytes per event): known answers and counted bad input."""

from evsync_testing.messages import mono_payload
from msg_adapters.mono import MonoDecoder


def test_fields_and_times_known_answer():
    payload = mono_payload(dt=[0, 7, (1 << 32) - 1], x=[0, 65535, 12], y=[32767, 0, 5], p=[1, 0, 1])
    ev = MonoDecoder().decode(payload, time_base=10**18, xyp=True)
    assert ev.t.tolist() == [10**18, 10**18 + 7, 10**18 + (1 << 32) - 1]
    assert (ev.x.tolist(), ev.y.tolist(), ev.p.tolist()) == ([0, 65535, 12], [32767, 0, 5], [1, 0, 1])


def test_backward_dt_and_trailing_bytes_are_counted():
    dec = MonoDecoder()
    ev = dec.decode(mono_payload([5, 3], [0, 0], [0, 0], [0, 0]) + b'\x00' * 5, time_base=0)
    assert ev.t.tolist() == [5, 3]
    assert dec.anomalies == {'trailing bytes (not a whole mono event)': 5, 'time going backwards within a message': 1}
