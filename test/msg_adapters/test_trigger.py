"""trigger (deprecated): recognised, no contrast events, edges readable."""

from evsync_testing.messages import mono_payload
from msg_adapters.trigger import TriggerDecoder


def test_no_contrast_events_but_edges_readable():
    payload = mono_payload(dt=[100, 200], x=[0, 0], y=[0, 0], p=[1, 0])  # same bit layout: edge bit 63, dt
    dec = TriggerDecoder()
    assert dec.decode(payload, time_base=1_000, xyp=True).t.size == 0
    t, edge = TriggerDecoder.triggers(payload, time_base=1_000)
    assert (t.tolist(), edge.tolist()) == ([1_100, 1_200], [1, 0])
    dec.decode(payload + b'\x00', time_base=0)
    assert dec.anomalies == {'trailing bytes (not a whole trigger)': 1}
