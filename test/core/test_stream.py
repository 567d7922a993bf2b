"""The engine streamed gives what it gives on whole arrays, offline and live, in bounded memory."""

import numpy as np
import pytest

from evsync_ros.core.engine import Engine, EngineParams, State
from evsync_ros.core.engine.arrays import estimate_offsets
from evsync_ros.core.engine.drivers import Offline
from evsync_ros.core.engine.drivers.passes import Feeder
from evsync_ros.core.paper import PaperParams
from evsync_ros.core.refined import RefinedParams
from evsync_ros.errors import StreamError
from evsync_testing.streams import bursty, thinned

MS = 1_000_000
S = 1_000_000_000


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
        engine = Engine(streams, reference='/ref', params=EngineParams(refined=RefinedParams(drift=False)),
                        driver=Offline())
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


def messages(streams, latency_ns=2 * MS, chunk_s=0.05):
    """Each stream's chunks with their arrival time on one host clock (the reference's, plus a
    latency), in the order a host receives them."""
    out = []
    for topic, t in streams.items():
        edges = np.searchsorted(t, np.arange(t[0], t[-1] + 1, int(chunk_s * 1e9)))
        for a, b in zip(edges, list(edges[1:]) + [t.size]):
            if b > a:
                out.append((int(t[b - 1]) + offsets.get(topic, 0) + latency_ns, topic, t[a:b]))
    return sorted(out, key=lambda m: m[0])


def test_the_papers_loop_is_one_plan_offline_and_live():
    # one recording through the engine's paper loop three ways: as arrays (no arrival times: each
    # camera's windows from its first event, as the paper's), streamed as a bag feeds it (arrival
    # times), and live (stepped by a timer, locking as it goes): the same windows, the same answer
    streams, truth = rig(35, seed=40)
    params = EngineParams(method='paper', paper=PaperParams())
    arrays = estimate_offsets(streams, reference='/ref', params=params.paper)
    engine = Engine(streams, reference='/ref', params=params, driver=Offline())
    feeder = Feeder(engine)
    live = Engine(streams, reference='/ref', params=params)
    locked_at = {}
    for i, (when, topic, part) in enumerate(messages(streams)):
        if not feeder.done:
            feeder.add(topic, part, when)
        live.add(topic, part, when)
        if i % 20 == 0:
            live.step(when)
            locked_at.update({t: when for t in truth if live.state(t) is State.LOCKED and t not in locked_at})
    assert engine.done  # every camera's loop ended: the reader stopped early
    offline = engine.finish()
    for topic, true in truth.items():
        bag, mine = engine.paper_estimate(topic), arrays[topic]
        assert bag.accepted and mine.accepted and offline[topic].accepted
        assert abs(bag.offset_ns - true) <= 3 * MS // 2 and abs(mine.offset_ns - bag.offset_ns) <= MS
        assert [w.index for w in bag.windows] == [w.index for w in mine.windows]
        st = live.status(topic)
        assert st.state is State.LOCKED and st.correction.offset_ns == bag.offset_ns
        assert live.paper_estimate(topic).windows == bag.windows  # window for window
        assert locked_at[topic] < int(streams['/ref'][0]) + (bag.window.index + 1) * 10 * S + 2 * S


def test_the_papers_loop_ends_at_its_first_accepted_window_and_live_stays_locked():
    streams, truth = rig(45, seed=41)
    live = Engine(streams, reference='/ref', params=EngineParams(method='paper'))
    for i, (when, topic, part) in enumerate(messages(streams)):
        live.add(topic, part, when)
        if i % 20 == 0:
            live.step(when)
    for topic in truth:
        loop = live.paper_estimate(topic)
        assert loop.accepted and loop.windows[-1] is loop.window  # nothing tried after it
        assert live.status(topic).windows_tried == len(loop.windows) < 4
        assert live.state(topic) is State.LOCKED


def test_a_stream_without_events_is_a_clear_error():
    streams, _ = rig(12, seed=50)
    engine = Engine([*streams, '/silent'], reference='/ref', driver=Offline())
    feed(Feeder(engine), streams)
    with pytest.raises(StreamError, match='/silent'):
        engine.finish()
    with pytest.raises(StreamError, match='/nope'):
        Engine(['/a', '/b'], reference='/nope')


def test_a_camera_locked_by_the_papers_loop_is_locked_again_when_back_from_a_silence():
    streams, _ = rig(30, seed=42)
    live = Engine(streams, reference='/ref', params=EngineParams(method='paper'))
    gap_from, gap_to = int(streams['/ref'][0]) + 20 * S, int(streams['/ref'][0]) + 24 * S
    for i, (when, topic, part) in enumerate(messages(streams)):
        if topic == '/b' and gap_from < when < gap_to:
            continue  # '/b' falls silent for 4 s after its loop has ended
        live.add(topic, part, when)
        if i % 20 == 0:
            live.step(when)
        if gap_from + 3 * S < when < gap_to:
            assert live.state('/b') is State.LOST
    assert live.state('/b') is State.LOCKED and live.status('/b').correction.offset_ns == live.paper_estimate(
        '/b').offset_ns


def test_the_papers_one_partial_window_of_a_short_camera_beside_a_long_reference():
    # a camera of 8 s (shorter than T) beside 100 s of the reference: its loop's one partial window
    # needs the reference's bins of its start, which a long recording would otherwise have freed
    ref = bursty(100, seed=43)
    clip = ref[ref < int(ref[0]) + 8 * S]  # both start together, as the paper has it
    cam = thinned(clip, 0.5, seed=44) - 6_997_000_000
    arrays = estimate_offsets({'/ref': ref, '/cam': cam}, reference='/ref')['/cam']
    assert arrays.accepted and abs(arrays.offset_ns - 6_997_000_000) <= 3 * MS // 2, arrays
    engine = Engine(['/ref', '/cam'], reference='/ref', params=EngineParams(method='paper'), driver=Offline())
    feeder = Feeder(engine)
    offsets['/cam'] = 6_997_000_000
    for when, topic, part in messages({'/ref': ref, '/cam': cam}):
        feeder.add(topic, part, when)
    del offsets['/cam']
    streamed = engine.finish()['/cam']
    assert streamed.accepted and streamed.offset_ns == engine.paper_estimate('/cam').offset_ns
    assert abs(streamed.offset_ns - 6_997_000_000) <= 3 * MS // 2
