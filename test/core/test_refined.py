"""The refined estimator: known answers for each feature, and the cases its confidence must reject."""

import math
from typing import Any

import numpy as np
import pytest

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.refined import RefinedParams, _gaussian, _gaussian_spectrum, estimate_rig, fit_camera, ncc_all_lags
from evsync_ros.core.results import WindowFit
from evsync_ros.errors import ParameterError, StreamError
from evsync_ros.testing.streams import BASE, bursty, jittered, thinned


def test_ncc_is_normalised_per_lag_overlap():
    a = np.array([0.0, 1, 0, 3, 0, 0])
    b = np.concatenate([np.zeros(4), a * 5 + 2, np.zeros(4)])
    ncc, count = ncc_all_lags(a, b)
    assert np.nanargmax(ncc) == 4 and ncc[4] == pytest.approx(1.0)
    assert count[4] == 6 and count[0] == 6 and count[-1] == 1



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


@pytest.mark.parametrize('sigma_bins', [5.0, 10.0, 20.0])
def test_fft_smoothing_is_the_direct_convolution_away_from_the_ends(sigma_bins):
    x = np.random.default_rng(1).poisson(2, 3000).astype(float)
    kernel = _gaussian(sigma_bins)
    h = (kernel.size - 1) // 2
    size = 4096
    smoothed = np.fft.irfft(np.fft.rfft(x, size) * _gaussian_spectrum(sigma_bins, size), size)[:x.size]
    direct = np.convolve(x, kernel, mode='same')
    assert np.allclose(smoothed[h:x.size - h], direct[h:x.size - h], rtol=0, atol=1e-12)

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



@pytest.mark.parametrize(('case', 'expected_sigma', 'worst_sigma'), [('sharp', 500_000, 2_000_000),
                                                                     ('jittered', 2_000_000, 500_000)])
def test_the_smoothing_follows_how_far_the_envelopes_agree(case, expected_sigma, worst_sigma):
    # sharp: both cameras share the activity's 1 ms edges, which a wide Gaussian blunts;
    # jittered: every event of both cameras scatters by 1.5 ms, which a narrow one follows
    true = 45_678
    errors: dict[Any, list[int]] = {}
    for sigma in (RefinedParams().smooth_ns, expected_sigma, worst_sigma):
        errors[sigma] = []
        for seed in range(4):
            activity = bursty(25, seed=100 + seed)
            if case == 'sharp':
                ref, cam = activity, thinned(activity, 0.5, seed=200 + seed)
            else:
                ref = jittered(activity, 0.7, 1_500_000, 300 + seed)
                cam = jittered(activity, 0.7, 1_500_000, 400 + seed)
            params = RefinedParams(drift=False, smooth_ns=sigma)
            fit = fit_camera(ref, cam - true, topic='cam', prior_ns=0, params=params)
            errors[sigma].append(abs(fit.offset_ns - true))
    assert RefinedParams().smooth_ns == (500_000, 1_000_000, 2_000_000)
    assert errors[RefinedParams().smooth_ns] == errors[expected_sigma]  # the default chose this sigma every time
    assert np.mean(errors[worst_sigma]) > 2.5 * np.mean(errors[expected_sigma])  # and the choice matters

def test_no_motion_is_rejected():
    rng = np.random.default_rng(5)
    ref = np.sort(rng.integers(0, 20 * 10**9, 400_000)) + BASE  # background noise only
    cam = np.sort(rng.integers(0, 20 * 10**9, 300_000)) + BASE
    fit = fit_camera(ref, cam, topic='cam', prior_ns=0)
    assert not fit.accepted and fit.confidence < 0.2


def test_periodic_motion_is_rejected_as_ambiguous():
    ms = np.arange(20_000)
    envelope = (np.sin(2 * np.pi * ms / 250.0) > 0.9).astype(float) * 40  # a 4 Hz flicker, nothing else
    rng = np.random.default_rng(6)
    n = rng.poisson(envelope)
    ref = np.sort(np.repeat(ms * 1_000_000, n) + rng.integers(0, 1_000_000, n.sum())) + BASE
    cam = thinned(ref, 0.5, seed=7) - 1_000_000
    fit = fit_camera(ref, cam, topic='cam', prior_ns=0)
    assert not fit.accepted
    window = fit.windows[0]
    assert window.peak > 0.5  # it correlates well ... at many shifts


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
    assert set(out['cameras'][1]) == {'topic', 'offset_ns', 'skew_ppm', 'anchor_ns', 'accepted', 'cost',
                                      'confidence', 'window_ns'}


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


def test_drift_line_is_not_dragged_by_one_window_the_scene_pulled_away():
    from evsync_ros.core.refined import fit_line
    params = RefinedParams()
    half = params.window_ns // 2
    rng = np.random.default_rng(4)
    xs = [5_000_000_000 * (k + 1) for k in range(11)]  # window centres on the camera's timeline
    ys = [1_000_000 + 20e-6 * (x - xs[0]) + rng.normal(0, 5_000) for x in xs]  # 20 ppm, 5 us scatter
    ys[0] -= 250_000  # the first window pulled 250 us away
    fits = [WindowFit(ref_start_ns=int(x - half + y), offset_ns=int(y), peak=0.9, confidence=0.5, accepted=True)
            for x, y in zip(xs, ys)]
    offset, skew, anchor, se = fit_line(fits, params)
    plain = np.polyfit(np.array(xs, float), np.array(ys), 1)[0] * 1e6
    assert abs(plain - 20.0) > 2.0  # least squares follows the outlier by ppm
    assert abs(skew - 20.0) < 0.5 and se < 0.5
    assert abs(offset - (1_000_000 + 20e-6 * (anchor - xs[0]))) < 5_000


def test_a_line_needs_three_windows_and_the_robust_fit_five():
    from evsync_ros.core.refined import MIN_DRIFT_WINDOWS, fit_line
    params = RefinedParams()
    half = params.window_ns // 2
    xs = [5_000_000_000 * (k + 1) for k in range(4)]
    ys = [1_000_000 + 30e-6 * (x - xs[0]) + e for x, e in zip(xs, (0, 4_000, -4_000, 0))]  # 30 ppm
    fits = [WindowFit(ref_start_ns=int(x - half + y), offset_ns=int(y), peak=0.9, confidence=0.5, accepted=True)
            for x, y in zip(xs, ys)]
    assert MIN_DRIFT_WINDOWS > 3
    for n in (3, 4):  # fewer windows than the default asks: offsets averaged unless the caller asks for fewer
        assert fit_line(fits[:n], params)[1:4:2] == (0.0, math.inf)
        _, skew, _, se = fit_line(fits[:n], params, min_windows=3)
        slope = np.polyfit(np.array(xs[:n], float), np.array(ys[:n]), 1)[0] * 1e6
        assert skew == pytest.approx(slope, abs=1e-6) and abs(skew - 30.0) < 2.0 and 0 < se < 2.0
    assert fit_line(fits[:2], params, min_windows=2)[1] == 0.0  # two windows leave no error for a slope
