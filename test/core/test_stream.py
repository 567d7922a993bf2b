"""The streamed estimators give what the whole-array ones give, in any chunking, in bounded memory."""

import numpy as np
import pytest

from evsync_ros.core.engine import Engine, OnlineParams
from evsync_ros.core.engine.offline import Feeder
from evsync_ros.core.paper import PaperParams, estimate_offsets
from evsync_ros.core.refined import RefinedParams
from evsync_ros.core.stream import PaperStream
from evsync_ros.errors import StreamError
from evsync_testing.streams import bursty, thinned


def feed(stream, streams, chunk_s=0.05):
    """Interleave the streams' chunks by reference time, as a recorder writes messages."""
    chunks = []
    for topic, t in streams.items():
        edges = np.searchsorted(t, np.arange(t[0], t[-1] + 1, int(chunk_s * 1e9)))
        for a, b in zip(edges, list(edges[1:]) + [t.size]):
            if b > a:
                chunks.append((int(t[a]) + offsets.get(topic, 0), topic, t[a:b]))
    for _, topic, part in sorted(chunks, key=lambda c: c[0]):
        stream.add(topic, part)


offsets: dict[str, int] = {}


def rig(seconds=40, seed=20):
    ref = bursty(seconds, seed=seed)
    truth = {'/b': 2_345_678, '/c': -1_000_000_000_123}
    offsets.update(truth)
    cams = {k: thinned(ref, 0.5, seed=seed + i + 1) - v for i, (k, v) in enumerate(truth.items())}
    return {'/ref': ref, **cams}, truth


def test_the_engine_offline_holds_memory_that_follows_the_window_not_the_length():
    peaks = []
    for seconds in (80, 320):  # both past the span at which the windows are as long as they get
        streams, truth = rig(seconds, seed=30)
        engine = Engine(streams, reference='/ref', params=OnlineParams(refined=RefinedParams(drift=False)),
                        offline=True)
        feeder = Feeder(engine)
        peak = 0
        chunks = sorted(((int(t[i]) + offsets.get(k, 0), k, t[i:i + 2000])
                         for k, t in streams.items() for i in range(0, t.size, 2000)), key=lambda c: c[0])
        for _, k, part in chunks:
            feeder.add(k, part)
            peak = max(peak, engine.nbytes)
        found = engine.finish()
        assert all(found[t].accepted and abs(found[t].offset_ns - v) < 100_000 for t, v in truth.items())
        peaks.append(peak)
    assert peaks[1] <= peaks[0] * 1.25  # four times the recording, the same bins held


def test_paper_stream_equals_the_paper_and_stops_when_all_are_accepted():
    streams, truth = rig(35, seed=40)
    params = PaperParams()
    s = PaperStream(streams, reference='/ref', params=params)
    feed(s, streams)
    got = s.finish()
    whole = estimate_offsets(streams, reference='/ref', params=params)
    for topic in truth:
        assert got[topic].offset_ns == whole[topic].offset_ns and got[topic].accepted == whole[topic].accepted
        assert [w.cost for w in got[topic].windows] == pytest.approx([w.cost for w in whole[topic].windows])
    assert s.done == all(e.accepted for e in whole.values())


def test_a_stream_without_events_is_a_clear_error():
    streams, _ = rig(12, seed=50)
    engine = Engine([*streams, '/silent'], reference='/ref', offline=True)
    feed(Feeder(engine), streams)
    with pytest.raises(StreamError, match='/silent'):
        engine.finish()
    with pytest.raises(StreamError, match='/nope'):
        Engine(['/a', '/b'], reference='/nope')
