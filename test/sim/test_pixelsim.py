"""The per-pixel simulator: deterministic, physical (thresholds and photoreceptors make lag), clocks."""

from dataclasses import replace

import numpy as np
import pytest

from evsync_ros.core.engine.arrays import fit_camera
from evsync_ros.core.refined import RefinedParams
from evsync_ros.errors import ParameterError
from evsync_ros.sim.pixelsim import NS, PRESETS, PixelCamera, Rig, Scene, camera_clock, preset, simulate


def _rig(*cams, seconds=6, seed=1, **scene):
    return Rig(cameras=cams, scene=Scene(duration_ns=seconds * NS, **scene), seed=seed)


def test_deterministic_by_seed():
    rig = _rig(PixelCamera('/a', noise_hz=0.0), seconds=3)
    a, b = simulate(rig)['/a'], simulate(rig)['/a']
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.x, b.x)
    c = simulate(replace(rig, seed=2))['/a']
    assert c.t.size != a.t.size or not np.array_equal(c.t, a.t)


def test_events_come_from_motion_not_from_a_still_world():
    moving = simulate(_rig(PixelCamera('/a', noise_hz=0.0, hot_pixels=0)))['/a']
    still = simulate(_rig(PixelCamera('/a', noise_hz=0.0, hot_pixels=0), motion='still'))['/a']
    assert moving.t.size > 50_000 and still.t.size == 0
    assert set(np.unique(moving.p)) == {0, 1}
    assert moving.x.max() < 64 and moving.y.max() < 48


def _lag_ns(slow_kwargs):
    base = PixelCamera('/fast', noise_hz=0.0, hot_pixels=0)
    slow = replace(base, topic='/slow', **slow_kwargs)
    ev = simulate(_rig(base, slow, seconds=12))
    ref = np.rint(ev['/fast'].true_t).astype(np.int64)
    cam = np.rint(ev['/slow'].true_t).astype(np.int64)
    fit = fit_camera(ref, cam, topic='/slow', prior_ns=0, params=RefinedParams(drift=False, window_ns=10 * NS))
    return -fit.offset_ns  # how much later the slow camera's envelope comes, in true time


def test_a_slower_photoreceptor_fires_later_and_a_higher_threshold_only_at_onsets():
    # the lag density methods cannot see past: in true time, the envelope of the slow camera trails
    assert 1_000_000 < _lag_ns({'lowpass_ns': 2_000_000}) < 2_500_000
    # integrate-and-fire fires when the level is crossed, so a higher threshold delays only the first
    # event after each still spell: a small net lag, well under a millisecond
    assert abs(_lag_ns({'contrast': 0.4})) < 200_000


def test_clock_skew_and_start():
    cam = PixelCamera('/a', start_ns=2 * NS, clock_at_start_ns=10**18, skew_ppm=50.0)
    assert camera_clock(cam, np.array([2 * NS, 12 * NS])).tolist() == [10**18, 10**18 + 10 * NS + 500_000]
    ev = simulate(_rig(cam, seconds=4))['/a']
    assert ev.true_t.min() >= 2 * NS and ev.t[0] >= 10**18


@pytest.mark.parametrize('name', list(PRESETS))
def test_every_preset_builds(name):
    rig = preset(name, seed=3)
    assert rig.reference == rig.cameras[0].topic and len(rig.cameras) >= 2


def test_bad_rigs_are_refused():
    with pytest.raises(ParameterError):
        PixelCamera('/a', contrast=0)
    with pytest.raises(ParameterError):
        Rig(cameras=(PixelCamera('/a'), PixelCamera('/a')))
    with pytest.raises(ParameterError, match='unknown preset'):
        preset('nope')


def test_each_camera_s_imu_measures_the_rig_s_turning_on_the_camera_s_clock():
    cams = (PixelCamera('/a', skew_ppm=30.0, clock_at_start_ns=5 * NS),
            PixelCamera('/b', yaw_deg=180.0, start_ns=NS // 2))
    rig = _rig(*cams, seconds=6, seed=3, motion='steady')
    with_imu, without = simulate(rig, imu_hz=500.0), simulate(rig)
    for cam in cams:
        imu = with_imu[cam.topic].imu
        assert imu is not None and without[cam.topic].imu is None
        np.testing.assert_array_equal(with_imu[cam.topic].t, without[cam.topic].t)  # the events are the same
        np.testing.assert_array_equal(imu.t, camera_clock(cam, imu.true_t))  # stamped on the camera's clock
        assert imu.true_t[0] >= cam.start_ns and np.allclose(np.diff(imu.true_t), 2e6)
        # 'steady' turns the rig at 60 deg/s about the vertical: the gyro's y axis sees it, noise and bias aside
        assert abs(np.median(-imu.gyro[:, 1]) - np.deg2rad(60.0)) < 0.02
        assert 0.001 < np.std(np.diff(imu.gyro[:, 2])) / np.sqrt(2) < 0.006  # white noise of ~0.003 rad/s
        assert abs(np.median(np.linalg.norm(imu.accel, axis=1)) - 9.81) < 0.1  # gravity
    # the pitch wobble reaches the two cameras' x axes with opposite signs (they face opposite ways)
    a, b = with_imu['/a'].imu, with_imu['/b'].imu
    assert a is not None and b is not None
    n = min(a.gyro.shape[0], b.gyro.shape[0])
    assert np.corrcoef(a.gyro[-n:, 0], b.gyro[-n:, 0])[0, 1] < -0.5
    with pytest.raises(ParameterError, match='imu_hz'):
        simulate(rig, imu_hz=5000.0)
