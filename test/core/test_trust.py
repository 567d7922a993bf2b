"""Trust (issue 21): an offset is accepted only when independent windows agree on it, and what is
accepted is right. Virtual rigs cut from real recordings (``evsync_testing.virtual``), whose
true offsets are known, and simulated rigs the old acceptance rule got wrong. Each of these but the
real fan failed on the estimator before the agreement rule (docs/benchmarks.md, "Real recordings")."""

import math
from dataclasses import replace

import numpy as np
import pytest

from evsync_ros.core.engine import Engine, State
from evsync_ros.core.engine.arrays import arriving, estimate_rig, estimate_times, fit_camera
from evsync_ros.core.refined import MODEL_SYSTEMATIC_NS, RefinedParams
from evsync_ros.core.results import CameraFit
from evsync_ros.sim import pixelsim, simbag
from evsync_testing.realdata import read_events
from evsync_testing.rigs import recorded
from evsync_testing.virtual import Case, virtual_rig, virtual_rig_arriving

MS = 1_000_000
S = 1_000_000_000


@pytest.fixture(scope='module')
def evk4(real_data):
    (events,) = read_events(real_data / 'evk4_hd').values()
    return events


def _estimate(case: Case, events) -> tuple[CameraFit, float, int]:
    """The refined estimate of the virtual rig's second camera, its error (ns) at the middle of that
    camera's recording, and that middle (camera time)."""
    times, truth = virtual_rig(case, events)
    fit = fit_camera(times['/a'], times['/b'], topic='/b', params=RefinedParams())
    mid = int(np.median(times['/b']))
    return fit, float(simbag.error_ns(fit.as_json(), truth, mid)), mid


@pytest.mark.parametrize('split', ['parity', 'random'])
def test_a_camera_that_starts_late_is_placed_to_tens_of_microseconds(evk4, split):
    # before: one 10 s window whose late-start edge read as a drop in activity, accepted 0.4 s off
    fit, err, _ = _estimate(Case('trust', 'late', 'evk4_hd', split, offset_ns=37 * MS + 412_345, late_ns=300 * MS,
                              keep=0.5, seed=1), evk4)
    assert fit.accepted, fit.reason
    assert abs(err) < 50_000
    assert abs(err) < 3 * fit.uncertainty_ns


@pytest.mark.parametrize('offset_ns', [1 * MS, -2_345 * MS - 555_555, 3_987 * MS + 123])
def test_a_clean_real_split_is_not_biased(evk4, offset_ns):
    # before: accepted 0.53-0.69 ms off where a plain cross-correlation is within 0.02 ms
    fit, err, _ = _estimate(Case('trust', 'clean', 'evk4_hd', 'parity', offset_ns=offset_ns), evk4)
    assert fit.accepted, fit.reason
    assert abs(err) < 50_000


@pytest.mark.parametrize('cut', [{'early_ns': 2 * S}, {'early_ns': 500 * MS, 'late_ns': 100 * MS}])
def test_a_camera_that_stops_early_is_placed_to_tens_of_microseconds(evk4, cut):
    fit, err, _ = _estimate(Case('trust', 'early', 'evk4_hd', 'random', offset_ns=912 * MS + 77_001, seed=3, **cut),
                         evk4)
    assert fit.accepted, fit.reason
    assert abs(err) < 50_000


@pytest.mark.parametrize('variant', [{}, {'jitter_ns': 1_000_000}, {'skew_ppm': -60.0, 'keep': 0.4}])
def test_cameras_seeing_different_parts_of_a_scene_are_never_accepted_wrong(evk4, variant):
    # the sensor's left and right halves: before issue 21, accepted 8.3 s and 9.8 s off. Their windows
    # searched +-5 s mostly peak elsewhere; since issue 50 they are searched again about where their
    # peaks point (evidence.vote), and accepted only where enough of them agree there
    fit, err, _ = _estimate(Case('trust', 'halves', 'evk4_hd', 'halves', offset_ns=-2_345 * MS, seed=4, **variant),
                            evk4)
    if fit.accepted:
        assert fit.uncertainty_ns is not None and abs(err) < 3 * fit.uncertainty_ns, (err, fit.uncertainty_ns)
        assert 'peaks point at' in fit.prior_reason
    else:
        assert fit.reason.startswith('windows disagree') and fit.uncertainty_ns is None


@pytest.mark.parametrize('split', ['parity', 'random'])
@pytest.mark.parametrize('make', [{'pixels': 4, 'threshold': 2, 'dead_ns': 1_000_000}, {'pixels': 4, 'threshold': 3}])
def test_a_coarser_less_sensitive_camera_of_another_make_is_placed_within_its_errors(evk4, split, make):
    # a DAVIS-like camera beside the EVK4: where the plain NCC is 0.3-11 ms off (bench/realrigs.py, make)
    fit, err, _ = _estimate(Case('trust', 'make', 'evk4_hd', split, offset_ns=912 * MS + 77_001, seed=5, **make),
                            evk4)
    assert fit.accepted, fit.reason
    assert abs(err) < 3 * fit.uncertainty_ns and abs(err) < 100_000, (err, fit.uncertainty_ns)
    halves, _, _ = _estimate(Case('trust', 'make', 'evk4_hd', 'halves', offset_ns=912 * MS + 77_001, seed=5, **make),
                             evk4)
    halves_err = _estimate(Case('trust', 'make', 'evk4_hd', 'halves', offset_ns=912 * MS + 77_001, seed=5, **make),
                           evk4)[1]
    assert (not halves.accepted and halves.reason.startswith('windows disagree')) or (
        halves.uncertainty_ns is not None and abs(halves_err) < 3 * halves.uncertainty_ns), halves.reason


@pytest.mark.parametrize(('split', 'motion_s'), [('parity', 3), ('random', 3), ('parity', 1), ('halves', 3)])
def test_motion_in_one_stretch_is_accepted_on_that_stretch(evk4, split, motion_s):
    """Issue 38: the recording's motion kept in its first seconds, a twentieth of its events after
    (a quiet scene). Before, refused: "windows disagree: at most 2 of the 4 windows"; the windows
    after the motion are quiet, not disagreeing, and the stretch decided on its own windows is right.
    The sensor's halves (different parts of the scene) are still not accepted."""
    t = evk4[0]
    kept = (t - t[0] < motion_s * S) | (np.random.default_rng(0).random(t.size) < 0.05)
    times, truth = virtual_rig(Case('trust', 'front', 'evk4_hd', split, offset_ns=37 * MS + 412_345),
                               tuple(a[kept] for a in evk4))
    fit = fit_camera(times['/a'], times['/b'], topic='/b', params=RefinedParams())
    if split == 'halves':
        assert not fit.accepted and fit.reason.startswith('windows disagree'), fit.reason
        return
    assert fit.accepted, fit.reason
    err = simbag.error_ns(fit.as_json(), truth, int(np.median(times['/b'])))
    assert abs(err) < max(3 * fit.uncertainty_ns, 50_000), (err, fit.uncertainty_ns)
    start = times['/a'][0]
    assert fit.window_ns[1] - start <= (motion_s + 2) * S  # decided on the stretch of motion
    assert fit.windows_total >= 3 and all(f.ref_start_ns + f.length_ns - start <= (motion_s + 2) * S
                                          for f in fit.windows)


@pytest.mark.parametrize('split', ['parity', 'random'])
def test_motion_in_one_stretch_is_decided_alike_live_and_offline(evk4, split):
    """The same rig with its arrival times: offline (``evsync estimate`` feeds a bag so) and the live
    engine stepped every 0.5 s of arrival time give one answer, accepted and locked."""
    t = evk4[0]
    kept = (t - t[0] < 3 * S) | (np.random.default_rng(0).random(t.size) < 0.05)
    times, arrivals, truth = virtual_rig_arriving(
        Case('trust', 'front', 'evk4_hd', split, offset_ns=37 * MS + 412_345), tuple(a[kept] for a in evk4))
    offline = estimate_rig(times, reference='/a', consistency=False, arrivals_ns=arrivals).camera('/b')
    msgs = sorted(((when, name, part) for name in times for part, when in arriving(times[name], arrivals[name])),
                  key=lambda m: m[0])
    live = Engine(['/a', '/b'], reference='/a')
    next_step = msgs[0][0] + S // 2
    for when, name, part in msgs:
        live.add(name, part, when)
        if when >= next_step:
            live.step(when)
            next_step += S // 2
    live.step(msgs[-1][0])
    status = live.status('/b')
    assert offline.accepted, offline.reason
    assert status.state is State.LOCKED, status.message
    assert abs(offline.offset_ns - truth['offset_ns']) < max(3 * offline.uncertainty_ns, 50_000)
    assert abs(status.correction.offset_ns - offline.offset_ns) <= 3 * math.hypot(offline.uncertainty_ns,
                                                                                  status.uncertainty_ns)


def test_two_makes_whose_windows_scatter_state_it_in_their_error():
    """Issue 38: make B of the two-makes-slow rig with a 1 ms refractory period at 1000 px/s (the
    response-lag grid's one wrong answer), through a rosbag2, estimated with the model term the bag
    tools add: its windows agree, but scatter about their line by 0.5 ms, which no window's error
    knows. Before, accepted 1.09 ms off at a stated 0.35 ms; the spread in the stated error makes it
    honest (or it is not accepted)."""
    rig, _, truth, times = recorded('two-makes-slow', 0, 12.0, speed_px_s=1000.0,
                                    make={'contrast': 0.22, 'refractory_ns': 1_000_000})
    models = {c['topic']: (c['encoding'], c['width'], c['height']) for c in truth['cameras']}
    systematic = {t: MODEL_SYSTEMATIC_NS if m != models[rig.reference] else 0.0 for t, m in models.items()}
    fit = estimate_times(times, reference=rig.reference, consistency=False, systematic_ns=systematic)
    (cam,) = [c for c in truth['cameras'] if c['topic'] != rig.reference]
    est = fit.camera(cam['topic'])
    if est.accepted:
        mid = int(np.median(times[cam['topic']]))
        err, se = abs(simbag.error_ns(est.as_json(), cam, mid)), est.uncertainty_at(mid)
        assert err <= 100_000 or err <= 3 * se, (err, se, est.spread_ns)
        assert est.spread_ns is not None and est.spread_ns > 0


@pytest.mark.parametrize('split', ['parity', 'random'])
@pytest.mark.parametrize('step', [(5 * S, 2 * S), (5 * S, -700 * MS), (7 * S, 30 * MS)])
def test_a_camera_whose_clock_jumps_is_not_accepted(evk4, split, step):
    # before: accepted, its one line 30 ms to 2 s off for the stretch on the other side of the jump
    # (events held in arrays, each with its arrival time on the host, as a bag holds them: a step too
    # near the end for the windows to see is seen in the arrival lags)
    case = Case('trust', 'step', 'evk4_hd', split, offset_ns=37 * MS + 412_345, seed=1, step=step)
    times, arrivals, _ = virtual_rig_arriving(case, evk4)
    fit = estimate_rig(times, reference='/a', consistency=False, arrivals_ns=arrivals).camera('/b')
    assert not fit.accepted
    assert 'clock step' in fit.reason or 'its clock jumped' in fit.reason, fit.reason
    assert fit.uncertainty_ns is None


def test_a_jittered_real_split_states_its_errors_honestly(evk4):
    # every event of the second camera late or early by a Gaussian of 1 ms. Before: the jackknife
    # left one block of ten out at a time, its replicates kept to the window's own noise bump, and it
    # understated the narrowest smoothing's errors six-fold (rms of error / standard error 6.7 over
    # these windows); three windows agreed to 0.03 ms on a point 0.29 ms off, and seed 106 was
    # accepted 9.4 standard errors off: wrong, by the benchmark's rule
    zs, within_3 = [], 0
    for seed in range(100, 110):
        fit, err, mid = _estimate(Case('trust', 'jitter', 'evk4_hd', 'parity', offset_ns=1 * MS, jitter_ns=1 * MS,
                                       seed=seed), evk4)
        assert fit.accepted, fit.reason
        se = fit.uncertainty_at(mid)
        assert se is not None and abs(err) < 5 * se, seed
        within_3 += abs(err) < 3 * se
        if fit.skew_ppm == 0:  # windows of one pass, on the truth's timeline (no skew: offset 1 ms throughout)
            zs += [(offset - 1 * MS) / w_se for w in fit.windows for sigma, offset, w_se in w.refined
                   if sigma == min(RefinedParams().sigmas_ns) and np.isfinite(w_se)]
    assert within_3 >= 9
    assert len(zs) >= 25
    assert float(np.sqrt(np.mean(np.square(zs)))) < 2.0


@pytest.mark.parametrize('seed', [104, 108])
def test_jitter_is_not_taken_for_a_skew(evk4, seed):
    # random pixel halves, one jittered by 1 ms, no skew. Before: 96 and 137 ppm fitted from five
    # windows at 3.1-3.2 of their scatter (Student's t for 3 degrees of freedom wants 9.2), and the
    # 137 ppm reported with no uncertainty, the second pass having found no residual skew
    case = Case('trust', 'jitter', 'evk4_hd', 'random', offset_ns=37 * MS, jitter_ns=1 * MS, seed=seed)
    times, truth = virtual_rig(case, evk4)
    fit = fit_camera(times['/a'], times['/b'], topic='/b', params=RefinedParams())
    assert fit.accepted, fit.reason
    if fit.skew_ppm:
        assert fit.skew_uncertainty_ppm is not None
        assert abs(fit.skew_ppm - truth['skew_ppm']) < 3 * fit.skew_uncertainty_ppm
    for t in (int(times['/b'][0]), int(np.median(times['/b'])), int(times['/b'][-1])):
        se = fit.uncertainty_at(t)
        assert se is not None and abs(simbag.error_ns(fit.as_json(), truth, t)) < 3 * se


def test_a_skew_kept_from_the_first_pass_keeps_its_uncertainty(evk4):
    case = Case('trust', 'skew', 'evk4_hd', 'parity', offset_ns=37 * MS, skew_ppm=100.0, seed=108)
    times, truth = virtual_rig(case, evk4)
    fit = fit_camera(times['/a'], times['/b'], topic='/b', params=RefinedParams())
    assert fit.accepted, fit.reason
    assert fit.skew_uncertainty_ppm is not None and fit.skew_uncertainty_ppm > 0
    assert abs(fit.skew_ppm - truth['skew_ppm']) < 3 * fit.skew_uncertainty_ppm


def test_an_opposite_facing_drifting_rig_gets_its_skew_within_a_ppm():
    # before: 10 of 12 windows rejected for modest peaks although 7 lay on the drift line; no skew
    # was fitted and the error grew to 2.4 ms by the end of 70 s
    rig = pixelsim.preset('opposite', seed=0, duration_s=70.0)
    ref_cam, cam = rig.cameras
    rig = replace(rig, cameras=(ref_cam, replace(cam, skew_ppm=40.0)))
    events = pixelsim.simulate(rig)
    ref_cam, cam = rig.cameras
    ref_t, cam_t = events[ref_cam.topic].t, events[cam.topic].t
    fit = fit_camera(ref_t, cam_t, topic=cam.topic, params=RefinedParams())
    assert fit.accepted, fit.reason
    true_skew = pixelsim.skew_against(ref_cam, cam)
    assert abs(fit.skew_ppm - true_skew) < 1.0
    for true_t in np.linspace(events[cam.topic].true_t[0], events[cam.topic].true_t[-1], 8):
        true_t = np.array([true_t])
        on_ref = int(pixelsim.camera_clock(ref_cam, true_t)[0])
        reading = int(pixelsim.camera_clock(cam, true_t)[0])
        assert abs(fit.correction.apply_one(reading) - on_ref) < 500_000


def _poisson(rate_hz: float, seconds: float, seed: int, *, envelope=None) -> np.ndarray:
    rng = np.random.default_rng(seed)
    ms = int(seconds * 1000)
    lam = rate_hz / 1000 * (np.ones(ms) if envelope is None else envelope(np.arange(ms)))
    n = rng.poisson(lam)
    t = np.repeat(np.arange(ms, dtype=np.int64) * MS, n) + rng.integers(0, MS, int(n.sum()))
    return np.sort(t) + 10**18


@pytest.mark.parametrize('rate_hz', [20_000, 200_000])
def test_flat_activity_is_not_accepted(rate_hz):
    # two cameras whose activity is steady and unrelated, over 5 s: nothing in time to align.
    # Before: accepted +123.6 ms, where the two recordings' edges line up
    ref, cam = _poisson(rate_hz, 5, 1), _poisson(rate_hz, 5, 2) - 123 * MS
    fit = fit_camera(ref, cam, topic='cam', params=RefinedParams())
    assert not fit.accepted and fit.reason


@pytest.mark.parametrize('shape', ['square', 'sine'])
def test_periodic_activity_is_not_accepted(shape):
    # a pendulum swinging every 1.7 s, seen by two cameras (each its own events) for 10 s: every
    # multiple of the period fits as well as the true offset. Before: accepted 0.3-0.4 ms off the
    # one the test put in, as if no other could be
    def pendulum(ms):
        phase = ms / 1700.0
        return 1.0 + (0.8 * ((ms // 850) % 2) if shape == 'square' else 0.9 * np.sin(2 * np.pi * phase))

    ref = _poisson(50_000, 10, 3, envelope=pendulum)
    cam = _poisson(30_000, 10, 4, envelope=pendulum) - 7 * MS - 250_000
    fit = fit_camera(ref, cam, topic='cam', params=RefinedParams())
    assert not fit.accepted and fit.reason


def test_a_real_fan_seen_by_a_stereo_pair_is_not_accepted(real_data):
    # a rotating fan: periodic, and the two retinas see it from different places (the estimator
    # before did not accept it either: this holds the new rule to it)
    events = read_events(real_data / 'dvs128_stereo' / 'fan')
    left, right = np.sort(events['/left/events'][0]), np.sort(events['/right/events'][0])
    fit = fit_camera(left, right, topic='/right/events', params=RefinedParams())
    assert not fit.accepted and fit.reason
