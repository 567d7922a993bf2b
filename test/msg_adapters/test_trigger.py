"""trigger (deprecated): recognised, no contrast events, edges readable (more in test_trigger_edges.py)."""

from msg_adapters.trigger import TriggerDecoder, encode_trigger


def test_no_contrast_events_but_edges_readable():
    payload = encode_trigger([100, 200], value=[1, 0], channel=[0, 5])
    dec = TriggerDecoder()
    assert dec.decode(payload, time_base=1_000, xyp=True).t.size == 0
    events, edges = dec.decode_edges(payload, time_base=1_000)
    assert len(events) == 0
    assert (edges.t.tolist(), edges.value.tolist(), edges.channel.tolist()) == ([1_100, 1_200], [1, 0], [0, 5])
    dec.decode(payload + b'\x00', time_base=0)
    assert dec.anomalies == {'trailing bytes (not a whole trigger)': 1}
