"""A rig on host time: the host line through the least arrival lags, and composing maps."""

import numpy as np
import pytest

from evsync_ros.core import host
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.errors import StreamError
from evsync_ros.core.host import HostEnvelope, arrival_offsets_ns, fit_host, lag_jumps

S = 1_000_000_000


def arrivals(rng, *, seconds, host: ClockCorrection, camera: ClockCorrection, floor_ns, jitter_ns, every_ns=1_000_000):
    """(camera-timeline event times, host arrival times) of a camera whose timeline maps onto the rig's
    by ``camera`` and the rig's onto host time by ``host``; arrival = host time + floor + exponential jitter."""
    t_cam = np.arange(0, seconds * S, every_ns, dtype=np.int64) + 5 * S
    true_host = host.apply(camera.apply(t_cam))
    return t_cam, true_host + floor_ns + rng.exponential(jitter_ns, t_cam.size).astype(np.int64)


def test_the_host_line_is_found_through_the_least_lags_of_every_camera():
    rng = np.random.default_rng(1)
    host = ClockCorrection(offset_ns=1_700_000_000 * S, skew_ppm=-42.0, anchor_ns=20 * S)
    cams = {'/a': ClockCorrection(), '/b': ClockCorrection(offset_ns=-3 * S, skew_ppm=55.0, anchor_ns=8 * S)}
    env = HostEnvelope()
    for topic, c in cams.items():
        t, arrive = arrivals(rng, seconds=60, host=host, camera=c, floor_ns=300_000, jitter_ns=2_000_000)
        for a, b in zip(t.tolist(), arrive.tolist()):
            env.add(topic, a, b)
    fit = fit_host(env, cams, floor_ns=300_000)
    assert abs(fit.skew_ppm - host.skew_ppm) < 0.5
    probe = np.array([6 * S, 30 * S, 60 * S], np.int64)
    for c in cams.values():
        got = c.then(fit.correction).apply(probe)
        np.testing.assert_allclose(got - host.apply(c.apply(probe)), 0, atol=100_000)  # 0.1 ms under 2 ms jitter
    assert fit.residual_ns < 100_000 and fit.segments > 200


def test_segments_where_every_message_came_late_are_dropped():
    rng = np.random.default_rng(2)
    host = ClockCorrection(offset_ns=S, skew_ppm=10.0)
    t, arrive = arrivals(rng, seconds=20, host=host, camera=ClockCorrection(), floor_ns=0, jitter_ns=300_000)
    late = (t > 10 * S) & (t < 11 * S)
    arrive[late] += 50_000_000  # a second in which the host was busy
    env = HostEnvelope()
    for a, b in zip(t.tolist(), arrive.tolist()):
        env.add('/a', a, b)
    fit = fit_host(env, {'/a': ClockCorrection()})
    assert fit.dropped >= 4
    assert abs(fit.correction.apply_one(15 * S) - host.apply_one(15 * S)) < 50_000


def test_too_short_or_no_corrected_camera_is_refused():
    env = HostEnvelope()
    env.add('/a', 0, 10)
    with pytest.raises(StreamError, match='putting the rig on the host clock needs messages in'):
        fit_host(env, {'/a': ClockCorrection()})
    with pytest.raises(StreamError, match='no camera'):
        fit_host(env, {'/b': ClockCorrection()})


@pytest.mark.parametrize('first', [ClockCorrection(),
                                   ClockCorrection(offset_ns=-7 * S, skew_ppm=80.0, anchor_ns=3 * S)])
@pytest.mark.parametrize('then', [ClockCorrection(offset_ns=1_763_700_000 * S, skew_ppm=-30.0, anchor_ns=9 * S),
                                  ClockCorrection(offset_ns=5)])
def test_then_is_one_map_for_two_anchored_where_the_second_is(first, then):
    t = np.array([0, 4 * S, 100 * S, 3600 * S], np.int64)
    both = first.then(then)
    np.testing.assert_allclose(both.apply(t), then.apply(first.apply(t)), atol=2)
    assert abs(both.offset_ns) < abs(then.offset_ns) + abs(first.offset_ns) + S  # not extrapolated to t = 0


def test_arrival_offsets_are_the_clocks_offsets_to_the_paths_latencies_whenever_each_camera_began():
    rng = np.random.default_rng(3)
    host = ClockCorrection(offset_ns=1_700_000_000 * S, skew_ppm=20.0, anchor_ns=0)
    cams = {'/ref': ClockCorrection(), '/late': ClockCorrection(offset_ns=-3 * S + 123_456, skew_ppm=-40.0,
                                                                 anchor_ns=30 * S)}
    env = HostEnvelope()
    for topic, c in cams.items():
        t, arrive = arrivals(rng, seconds=60, host=host, camera=c, floor_ns=300_000 if topic == '/ref' else 1_300_000,
                             jitter_ns=2_000_000)
        keep = t >= (25 * S if topic == '/late' else 0)  # began recording 20 s after the reference
        env.add_many(topic, t[keep], arrive[keep])
    got = arrival_offsets_ns(env, '/ref')
    assert set(got) == {'/late'}
    truth = cams['/late'].apply_one(45 * S) - 45 * S  # its offset mid-recording
    # the 1 ms longer path, and the host clock's 20 ppm over the 10 s between the two recordings' middles
    assert abs(got['/late'] - truth - 1_000_000) < 1_000_000
    assert arrival_offsets_ns(HostEnvelope(), '/ref') == {}


def test_a_lag_that_steps_is_a_jump_and_one_that_drifts_or_has_late_segments_is_not():
    rng = np.random.default_rng(4)
    t = np.arange(240, dtype=np.int64) * 250_000_000  # a minute of quarter-second segments
    drift = (t * 100e-6).astype(np.int64)  # 100 ppm against the host: 6 ms over the minute
    lag = 2_000_000 + drift + rng.exponential(200_000, t.size).astype(np.int64)
    lag[rng.choice(t.size, 12, replace=False)] += 80_000_000  # segments whose every message came late
    assert lag_jumps(t, lag) == []
    jumped = lag.copy()
    jumped[100:] -= 50_000_000  # the clock read 50 ms more from 25 s on
    (at, by), = lag_jumps(t, jumped)
    assert abs(at - 25 * S) <= 250_000_000 and abs(by + 50_000_000) < 1_000_000
    assert lag_jumps(t[:10], jumped[:10]) == []  # too few segments to tell


@pytest.mark.parametrize('seed', range(6))
def test_the_median_steps_are_those_of_each_window_taken_on_its_own(seed):
    """``lag_jumps``' steps, every window's median taken in one call (the live driver asks for them at
    each estimate), are those of two ``np.median`` calls a point, to the bit, on lags with jumps and
    late segments; and the jumps are found."""
    rng = np.random.default_rng(seed)
    n, side = int(rng.integers(2 * host.JUMP_SEGMENTS, 400)), host.JUMP_SEGMENTS
    t = np.arange(n, dtype=np.int64) * 250_000_000
    lag = 2_000_000 + rng.exponential(300_000, n).astype(np.int64)
    for at in rng.choice(n, 3, replace=False):
        lag[at:] += int(rng.choice([-1, 1])) * int(rng.integers(10, 200)) * 1_000_000
    lag[rng.choice(n, n // 20, replace=False)] += 80_000_000
    d = lag.astype(np.float64)
    alone = [np.median(d[k:k + side]) - np.median(d[k - side:k]) for k in range(side, n - side + 1)]
    assert host.median_steps(lag, side).tolist() == alone
    assert lag_jumps(t, lag)


def test_within_keeps_only_the_points_seen_inside_each_stream_s_events():
    env = HostEnvelope()
    for t in (1 * S, 2 * S, 3 * S, 900 * S):  # the last: a corrupt event time, far past the stream
        env.add('/a', t, t + 5_000_000)
    env.add('/b', 2 * S, 2 * S + 1_000_000)
    kept = env.within({'/a': (1 * S, 3 * S)})
    assert kept.topics == ['/a']
    assert kept.points('/a')[0].tolist() == [1 * S, 2 * S, 3 * S]
    assert env.points('/a')[0].size == 4  # the envelope itself is untouched
