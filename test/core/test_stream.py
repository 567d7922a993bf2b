"""The streamed estimators give what the whole-array ones give, in any chunking, in bounded memory."""

import numpy as np
import pytest

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine.arrays import fit_camera
from evsync_ros.core.paper import PaperParams, estimate_offsets
from evsync_ros.core.refined import RefinedParams, camera_result, deskew_of
from evsync_ros.core.stream import PaperStream, RefinedStream
from evsync_ros.errors import StreamError
from evsync_ros.testing.streams import BASE, bursty, thinned


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


def test_refined_stream_equals_fit_camera_window_by_window():
    streams, truth = rig()
    params = RefinedParams(drift=False)
    span = int(streams['/ref'][-1] - streams['/ref'][0]) + 1
    s = RefinedStream(streams, reference='/ref', params=params, span_ns=span)
    feed(s, streams)
    got = s.finish()
    assert s.nbytes < 8 * 10**6
    for topic in truth:
        whole = fit_camera(streams['/ref'], streams[topic], topic=topic, params=params)
        assert [w.ref_start_ns for w in got[topic]] == [w.ref_start_ns for w in whole.windows]
        assert [w.refined for w in got[topic]] == [w.refined for w in whole.windows]
        assert [w.confidence for w in got[topic]] == pytest.approx([w.confidence for w in whole.windows])
        fit = camera_result(topic, got[topic], params)
        assert (fit.offset_ns, fit.accepted, fit.uncertainty_ns) == (whole.offset_ns, whole.accepted,
                                                                     whole.uncertainty_ns)
        assert deskew_of(fit) is None and fit.accepted and abs(fit.offset_ns - truth[topic]) < 20_000
        best = max(got[topic], key=lambda w: w.confidence)
        assert best.ncc.size and sum(w.ncc.size > 0 for w in got[topic]) == 1  # one curve kept


def test_memory_follows_the_window_not_the_length():
    peaks = []
    for seconds in (40, 160):
        streams, _ = rig(seconds, seed=30)
        s = RefinedStream(streams, reference='/ref', params=RefinedParams(drift=False))
        peak = 0
        chunks = sorted(((int(t[i]) + offsets.get(k, 0), k, t[i:i + 2000])
                         for k, t in streams.items() for i in range(0, t.size, 2000)), key=lambda c: c[0])
        for _, k, part in chunks:
            s.add(k, part)
            peak = max(peak, s.nbytes)
        s.finish()
        peaks.append(peak)
    assert peaks[1] <= peaks[0] * 1.25  # four times the recording, the same bins held


def test_refined_stream_second_pass_recovers_the_skew():
    ref = bursty(70, seed=8)
    truth = ClockCorrection(offset_ns=-3_000_000, skew_ppm=40.0, anchor_ns=BASE + 30 * 10**9)
    cam = thinned(truth.inverse().apply(ref), 0.5, seed=9)
    streams = {'/ref': ref, '/cam': cam}
    params = RefinedParams()
    span = int(ref[-1] - ref[0]) + 1
    s = RefinedStream(streams, reference='/ref', params=params, span_ns=span)
    feed(s, streams)
    first = camera_result('/cam', s.finish()['/cam'], params)
    deskew = deskew_of(first)
    assert first.accepted and deskew is not None
    s2 = RefinedStream(streams, reference='/ref', params=params, corrections={'/cam': deskew},
                       priors_ns={'/cam': first.offset_ns}, span_ns=span)
    feed(s2, streams)
    fit = camera_result('/cam', s2.finish()['/cam'], params, skew_ppm=deskew.skew_ppm, anchor_ns=deskew.anchor_ns)
    whole = fit_camera(ref, cam, topic='/cam', params=params)
    assert fit.accepted and fit.skew_ppm == pytest.approx(whole.skew_ppm, abs=0.05)
    assert abs(fit.offset_ns - whole.offset_ns) < 2_000
    assert fit.skew_ppm == pytest.approx(40.0, abs=1.0)


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
    s = RefinedStream([*streams, '/silent'], reference='/ref')
    feed(s, streams)
    with pytest.raises(StreamError, match='/silent'):
        s.finish()
    with pytest.raises(StreamError, match='/nope'):
        RefinedStream(['/a'], reference='/nope')
