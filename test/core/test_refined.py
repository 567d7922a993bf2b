"""The refined estimator: known answers for each feature, and the cases its confidence must reject."""

import numpy as np
import pytest

from evsync_ros.core.bins import SortedTimes
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine.arrays import estimate_rig, fit_camera
from evsync_ros.core.refined import (
    JACKKNIFE_BLOCKS,
    REPLICATES,
    RefinedParams,
    _parabola,
    _peak,
    _recorded_spans,
    fit_window,
    masked_ncc,
    ncc_all_lags,
    with_smoothing,
)
from evsync_ros.errors import ParameterError, StreamError
from evsync_testing.streams import BASE, bursty, jittered, thinned


def test_ncc_is_normalised_per_lag_overlap():
    a = np.array([0.0, 1, 0, 3, 0, 0])
    b = np.concatenate([np.zeros(4), a * 5 + 2, np.zeros(4)])
    ncc, count = ncc_all_lags(a, b)
    assert np.nanargmax(ncc) == 4 and ncc[4] == pytest.approx(1.0)
    assert count[4] == 6 and count[0] == 6 and count[-1] == 1


@pytest.mark.parametrize('masks', ['camera', 'both'])
def test_masked_ncc_pairs_only_covered_bins_at_every_lag(masks):
    rng = np.random.default_rng(11)
    a, b = rng.poisson(3, 300).astype(float), rng.poisson(3, 700).astype(float)
    ma = np.ones(a.size, bool) if masks == 'camera' else rng.random(a.size) > 0.2
    mb = rng.random(b.size) > 0.3
    ncc, count = masked_ncc(a, ma, b, mb, lags=250)
    assert ncc.size == count.size == 250
    for m in range(250):
        i = np.arange(a.size)
        i = i[(i + m < b.size)]
        i = i[ma[i] & mb[i + m]]
        assert count[m] == i.size
        assert ncc[m] == pytest.approx(np.corrcoef(a[i], b[i + m])[0, 1], abs=1e-12)


def test_ncc_matches_a_direct_pearson_correlation_at_every_lag():
    rng = np.random.default_rng(7)
    a = rng.poisson(3, 40).astype(float)
    b = rng.poisson(2, 75).astype(float)
    b[20:25] = 4.0  # a lag whose overlap is partly constant still has a defined correlation
    ncc, count = ncc_all_lags(a, b)
    for m in range(b.size):
        k = min(a.size, b.size - m)
        assert count[m] == k
        x, y = a[:k], b[m:m + k]
        if k < 2 or np.ptp(x) == 0 or np.ptp(y) == 0:
            assert np.isnan(ncc[m])
        else:
            assert ncc[m] == pytest.approx(np.corrcoef(x, y)[0, 1], abs=1e-12)


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_the_peak_and_its_jackknife_are_those_of_the_correlations_computed_one_by_one(seed):
    rng = np.random.default_rng(seed)
    n, lags = 2003, 41
    a = rng.poisson(3, n).astype(float)
    b = np.convolve(rng.poisson(3, n + lags + 4).astype(float), np.ones(5) / 5, mode='valid')
    r = [np.corrcoef(a, b[k:k + n])[0, 1] for k in range(lags)]
    m = int(np.argmax(r))
    edges = np.linspace(0, n, JACKKNIFE_BLOCKS + 1).astype(int)
    peaks = []
    for kept_blocks in REPLICATES:  # each replicate leaves 3 blocks out and seeks its own peak at every lag
        keep = np.zeros(n, bool)
        for k in np.flatnonzero(kept_blocks):
            keep[edges[k]:edges[k + 1]] = True
        rr = [np.corrcoef(a[keep], b[lag:lag + n][keep])[0, 1] for lag in range(lags)]
        i = int(np.argmax(rr))
        peaks.append(i + (_parabola(rr[i - 1], rr[i], rr[i + 1]) if 0 < i < lags - 1 else 0.0))
    se = float(np.sqrt((JACKKNIFE_BLOCKS - 3) / 3 * np.mean((np.array(peaks) - np.mean(peaks)) ** 2)))
    got_m, got_frac, got_se = _peak(a, b, n, lags)
    assert got_m == m
    assert got_frac == pytest.approx(_parabola(r[m - 1], r[m], r[m + 1]), abs=1e-9)
    assert got_se == pytest.approx(se, rel=1e-9)


def test_the_replicates_leave_out_every_three_blocks_once():
    assert REPLICATES.shape == (120, JACKKNIFE_BLOCKS)
    assert (REPLICATES.sum(axis=1) == JACKKNIFE_BLOCKS - 3).all()
    assert ((1 - REPLICATES).sum(axis=0) == 36).all()  # every block left out equally often
    assert len({row.tobytes() for row in REPLICATES}) == REPLICATES.shape[0]


@pytest.mark.parametrize('true_ns', [123_456, -987_654, 2_400_000_321, -4_100_000_007])
def test_offset_to_microseconds_over_the_full_range(true_ns):
    ref = bursty(25, seed=1)
    cam = thinned(ref, 0.5, seed=2) - true_ns  # cam + true = ref
    fit = fit_camera(ref, cam, topic='cam', prior_ns=0, params=RefinedParams(drift=False))
    assert fit.accepted
    assert abs(fit.offset_ns - true_ns) < 20_000  # 1 ms bins, refined to well under 0.02 ms


def test_prior_from_first_events_finds_a_start_delay():
    ref = bursty(25, seed=3)
    cam = thinned(ref[ref > BASE + 1_300_000_000], 0.6, seed=4) - 5 * 10**18  # started 1.3 s later, other clock
    fit = fit_camera(ref, cam, topic='cam', params=RefinedParams(drift=False))
    assert fit.accepted and abs(fit.offset_ns - 5 * 10**18) < 20_000



@pytest.mark.parametrize(('case', 'narrow'), [('sharp', True), ('jittered', False)])
def test_the_smoothing_follows_how_far_the_envelopes_agree(case, narrow):
    # sharp: both cameras share the activity's events to the microsecond, which only a narrow
    # Gaussian keeps; jittered: every event of both cameras scatters by 1.5 ms, which a narrow one
    # follows into noise. The camera takes the smoothing its windows agree on most precisely.
    true = 45_678
    params = RefinedParams(drift=False)
    for seed in range(3):
        activity = bursty(25, seed=100 + seed)
        if case == 'sharp':
            ref, cam = activity, thinned(activity, 0.5, seed=200 + seed)
        else:
            ref = jittered(activity, 0.7, 1_500_000, 300 + seed)
            cam = jittered(activity, 0.7, 1_500_000, 400 + seed)
        fit = fit_camera(ref, cam - true, topic='cam', prior_ns=0, params=params)
        assert fit.accepted, fit.reason
        chosen = {w.smooth_ns for w in fit.windows}
        assert len(chosen) == 1  # one smoothing for every window of a camera
        sigma = chosen.pop()
        assert (sigma <= 500_000) == narrow, sigma
        assert abs(fit.offset_ns - true) <= 3 * fit.uncertainty_ns


def _poisson(rng: np.random.Generator, start: int, length: int, rate) -> np.ndarray:
    """Event times of a Poisson process of ``rate(t)`` events/s (t: ns from ``start``), by thinning."""
    top = float(rate(np.array([0.0]))[0]) * 1.2
    t = np.sort(rng.uniform(0, length, rng.poisson(top * length / 1e9)))
    return start + t[rng.random(t.size) < rate(t) / top].astype(np.int64)


@pytest.mark.parametrize('seed', range(4))
def test_a_window_where_both_recordings_start_mid_burst_is_not_pulled_by_the_empty_stretch(seed):
    # Both cameras start recording during a burst of activity; the camera's events scatter by 1 ms,
    # so the broad smoothings carry the offset. The refinement reads the camera a reach either side
    # of each reference bin: before, it read the stretch before the camera's first event as no
    # activity, and the broad smoothings' peaks leaned 0.55-1.8 ms (old code, these seeds).
    def rate(t):
        return 4e5 * np.exp(-t / 150e6) + 3e4 * (1 + 0.5 * np.sin(2 * np.pi * t / 37e6))

    rng = np.random.default_rng(seed)
    start, length, true = BASE, 2 * 10**9, 123_456_789
    ref = _poisson(rng, start, length, rate)
    cam = _poisson(rng, start, length, rate)
    cam = np.sort(cam + rng.normal(0, 1e6, cam.size).astype(np.int64))
    cam = cam[(cam >= start) & (cam < start + length)] - true  # the camera records the same stretch
    params = RefinedParams()
    fit = fit_window(SortedTimes(ref), SortedTimes(cam), ref_start_ns=start, length_ns=length,
                     prior_ns=true + 3_000_000, params=params)
    for sigma in (1_500_000, 3_000_000):
        w = with_smoothing(fit, sigma)
        assert abs(w.offset_ns - true) < 500_000, (sigma, w.offset_ns - true)
        assert abs(w.offset_ns - true) < 3 * w.se_ns


def test_each_smoothing_drops_only_the_bins_its_reach_takes_past_the_camera_s_recording():
    params = RefinedParams()
    mb = np.zeros(1000, dtype=bool)
    mb[100:900] = True  # the camera recorded bins 100-899 (coarse bins of the array it was read into)
    q = params.tau_ns // params.fine_ns
    # a span of reference bins [100, 800) paired at lag index 0: it starts where the camera's recording does
    spans = _recorded_spans(mb, 0, (100, 800), params)
    # in coarse bins: at least 2 ms of lags and 3 sigma of kernel, on each smoothing's own bins
    # (0.1, 0.2, 0.6 and 1.2 ms): 2.5, 3.6, 7.2 and 12 ms
    reach = {150_000: 3, 500_000: 4, 1_500_000: 8, 3_000_000: 12}
    assert spans == {sigma: (k * q, (700 - k) * q) for sigma, k in reach.items()}
    # the same span paired 50 bins later: the camera recorded 50 bins before it, every smoothing keeps it all
    assert _recorded_spans(mb, 50, (100, 800), params) == dict.fromkeys(reach, (0, 700 * q))
    # and where it ends with the camera's recording, the end is trimmed the same way
    ends = _recorded_spans(mb, 100, (100, 800), params)
    assert ends == {sigma: (0, (700 - k) * q) for sigma, k in reach.items()}


def test_no_motion_is_rejected():
    rng = np.random.default_rng(5)
    ref = np.sort(rng.integers(0, 20 * 10**9, 400_000)) + BASE  # background noise only
    cam = np.sort(rng.integers(0, 20 * 10**9, 300_000)) + BASE
    fit = fit_camera(ref, cam, topic='cam', prior_ns=0)
    assert not fit.accepted and fit.reason.startswith(('windows disagree', 'too flat')), fit.reason


def test_periodic_motion_is_rejected_as_ambiguous():
    # a 4 Hz flicker and nothing else, each camera its own events of it (a copy of the same events,
    # thinned, would share their fine timing, which is not periodic: that can be told apart)
    ms = np.arange(20_000)
    envelope = (np.sin(2 * np.pi * ms / 250.0) > 0.9).astype(float) * 40
    rng = np.random.default_rng(6)

    def events() -> np.ndarray:
        n = rng.poisson(envelope)
        return np.sort(np.repeat(ms * 1_000_000, n) + rng.integers(0, 1_000_000, n.sum())) + BASE

    ref, cam = events(), events() - 1_000_000
    fit = fit_camera(ref, cam, topic='cam', prior_ns=0)
    assert not fit.accepted, fit.reason
    window = fit.windows[0]
    assert window.peak > 0.5  # it correlates well ... at many shifts
    assert sum(v > 0.9 * window.peak for _, v in window.candidates) >= 2


def test_skew_from_successive_windows():
    ref = bursty(70, seed=8)
    truth = ClockCorrection(offset_ns=-3_000_000, skew_ppm=40.0, anchor_ns=BASE + 30 * 10**9)
    cam = thinned(truth.inverse().apply(ref), 0.5, seed=9)  # camera clock: ref = truth(cam)
    fit = fit_camera(ref, cam, topic='cam', prior_ns=0)
    assert fit.accepted
    assert fit.skew_ppm == pytest.approx(40.0, abs=1.0)
    t = cam[:: max(1, cam.size // 50)]
    err = fit.correction.apply(t) - truth.apply(t)
    assert np.abs(err).max() < 50_000


def test_n_cameras_and_the_pairwise_consistency_check():
    ref = bursty(25, seed=10)
    truths = {'/a': 0, '/b': 1_234_567, '/c': -3_210_000_000, '/d': 45_678}
    streams = {k: thinned(ref, 0.5, seed=i) - v for i, (k, v) in enumerate(truths.items())}
    rig = estimate_rig(streams, reference='/a', params=RefinedParams(drift=False))
    assert [c.topic for c in rig.cameras] == ['/a', '/b', '/c', '/d']
    for c in rig.cameras:
        assert c.accepted and abs(c.offset_ns - truths[c.topic]) < 20_000
    assert set(rig.pair_residual_ns) == {('/b', '/c'), ('/b', '/d'), ('/c', '/d')}
    assert max(abs(v) for v in rig.pair_residual_ns.values()) < 40_000
    out = rig.as_json()
    assert out['reference'] == '/a' and out['cameras'][0]['offset_ns'] == 0
    assert list(out['cameras'][1]) == ['topic', 'offset_ns', 'skew_ppm', 'anchor_ns', 'accepted', 'cost',
                                       'confidence', 'window_ns', 'uncertainty_ns', 'skew_uncertainty_ppm', 'reason',
                                       'windows_agreeing', 'windows_total', 'spread_ns', 'prior', 'prior_reason']


def test_bad_inputs_are_clear_errors():
    with pytest.raises(ParameterError):
        RefinedParams(fine_ns=300_000)  # tau not a multiple
    with pytest.raises(ParameterError):
        RefinedParams(min_confidence=float('nan'))
    with pytest.raises(StreamError, match="'/x'"):
        estimate_rig({'/a': bursty(1, 0), '/x': np.array([], np.int64)}, reference='/a')
    with pytest.raises(StreamError, match='reference'):
        estimate_rig({'/a': bursty(1, 0)}, reference='/b')


def test_a_known_envelope_latency_is_taken_out():
    ref = bursty(25, seed=11)
    # camera /b's envelope lags the world by 400 us more than the reference's; its clock is 2 ms behind
    lagging = thinned(ref, 0.5, seed=12) + 400_000 - 2_000_000
    rig = estimate_rig({'/a': ref, '/b': lagging}, reference='/a', params=RefinedParams(drift=False))
    raw = rig.cameras[1].offset_ns
    assert abs(raw - 1_600_000) < 20_000  # the envelopes align 400 us short of the clock offset
    fixed = rig.with_latencies({'/a': 100_000, '/b': 500_000})
    assert fixed.cameras[1].offset_ns == raw + 400_000 and fixed.cameras[0].offset_ns == 0
    with pytest.raises(StreamError, match='/nope'):
        rig.with_latencies({'/nope': 1})


class _Logged(SortedTimes):
    """A camera's events that note every stretch the estimator reads of them."""

    def __init__(self, times: np.ndarray) -> None:
        super().__init__(times)
        self.reads: list[tuple[int, int]] = []

    def counts(self, start_ns: int, bin_ns: int, n: int) -> np.ndarray:
        self.reads.append((start_ns, start_ns + n * bin_ns))
        return super().counts(start_ns, bin_ns, n)


def test_a_window_reads_the_camera_no_further_than_its_stated_reach():
    # the streamed and live paths keep a camera's counts only this far around a window (camera_reach_ns);
    # the truth 0.5 ms inside the search range's edge puts the refinement at the end of it. Before,
    # the reach said 11 ms where the broadest smoothing read 12 (its kernel on its own 1.2 ms bins)
    params = RefinedParams()
    ref = bursty(4, seed=11)
    true, length = 3_210_000, 2 * 10**9
    cam = _Logged(thinned(ref, 0.6, seed=12) - true)
    for prior in (true + params.max_shift_ns - 500_000, true - params.max_shift_ns + 500_000):
        cam.reads.clear()
        fit = fit_window(SortedTimes(ref), cam, ref_start_ns=int(ref[0]), length_ns=length, prior_ns=prior,
                         params=params)
        assert abs(fit.offset_ns - true) < 50_000  # found, at the edge of the range
        low = int(ref[0]) - prior - params.camera_reach_ns
        high = int(ref[0]) + length - prior + params.camera_reach_ns
        assert all(low <= a and b <= high for a, b in cam.reads), (low, high, cam.reads)
