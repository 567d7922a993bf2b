"""The paper-faithful estimator on hand-made densities and on simulated rigs with known offsets."""

import math

import numpy as np
import pytest

from evsync_ros.core import estimate_offset, estimate_offsets, paper
from evsync_ros.errors import ParameterError, StreamError
from evsync_ros.sim import rigsim

MS = 1_000_000
S = 1_000_000_000
# The paper's method works in whole bins of tau = 1 ms: the bins' phase against the true shift
# costs up to half a bin and noise can move the argmin by one more. 1.5 bins is its resolution.
TOL = 3 * MS // 2


def simulated_pair(delays_ns, clocks_ns, *, duration_ns=21 * S, seed=0):
    # One fixed scene where the paper's assumptions hold (motion episodes seen by both cameras
    # inside the window), two whole windows long so the epsilon loop can retry. The method's error
    # statistics over many scenes and seeds are the accuracy benchmark's business, not a unit test's.
    rig = rigsim.rig_from_start_delays(delays_ns, clocks_ns=clocks_ns, duration_ns=duration_ns, seed=seed)
    streams = rigsim.simulate_streams(rig)
    ref, cam = (c.topic for c in rig.cameras)
    return streams[ref], streams[cam], rig.true_offsets_ns()[cam]


def test_dissimilarity_sums_squared_differences_over_the_overlap_only():
    m_ref = np.array([0.1, 0.2, 0.3, 0.4])
    m_cam = np.array([0.4, 0.3, 0.2, 0.1])
    # shift 1: M_ref[1:4] against M_cam[0:3]
    assert paper.dissimilarity(m_ref, m_cam, 1) == pytest.approx(0.2**2 + 0.0 + 0.2**2)
    # shift -2: M_ref[0:2] against M_cam[2:4]
    assert paper.dissimilarity(m_ref, m_cam, -2) == pytest.approx(0.1**2 + 0.1**2)
    assert math.isnan(paper.dissimilarity(m_ref, m_cam, 4))


def test_search_range_is_centred_on_the_percentile_estimate_with_twice_its_size_each_side():
    m_ref = np.zeros(100)
    m_ref[30] = 1.0
    m_cam = np.zeros(100)
    m_cam[10] = 1.0
    # M_ref(t) = M_cam(t - 20): the percentile estimate of the shift is Q_ref - Q_cam = 20.
    assert paper.search_range(m_ref, m_cam, percentile=50) == (-20, 60)
    assert paper.search_range(m_cam, m_ref, percentile=50) == (-60, 20)


def test_degenerate_range_searches_the_single_candidate_zero():
    rng = np.random.default_rng(3)
    ref = np.sort(rng.integers(0, 10 * S, 200_000))
    est = estimate_offset(ref, ref.copy())
    assert est.window.search_range_bins == (0, 0)
    assert est.offset_ns == 0 and est.cost == 0.0 and est.accepted


@pytest.mark.parametrize(
    ('delays_ns', 'clocks_ns'),
    [
        pytest.param([0, 250 * MS], [0, 0], id='camera-starts-later'),
        pytest.param([180 * MS, 0], [0, 0], id='camera-starts-earlier'),
        pytest.param([0, 0], [0, 0], id='zero'),
        pytest.param([0, 41 * MS], [0, 7_300 * MS], id='clock-offset-beyond-half-window'),
        pytest.param([0, 1_348 * MS], [1_763_700_000 * S, 0], id='ros-time-against-sensor-time'),
        pytest.param([77 * MS, 0], [0, -6 * S], id='negative-beyond-half-window'),
    ],
)
def test_known_offsets_are_recovered_within_one_bin(delays_ns, clocks_ns):
    ref, cam, truth = simulated_pair(delays_ns, clocks_ns)
    est = estimate_offset(ref, cam)
    assert est.accepted, est.windows
    assert abs(est.offset_ns - truth) <= TOL, (est.offset_ns, truth)


def test_offset_sign_convention_restamping_by_the_offset_aligns_the_camera():
    ref, cam, truth = simulated_pair([0, 310 * MS], [0, 2 * S])
    est = estimate_offset(ref, cam)
    again = estimate_offset(ref, cam + est.offset_ns)
    assert abs(again.offset_ns) <= TOL
    assert truth < 0 and est.offset_ns < 0


def test_epsilon_loop_moves_on_to_the_next_window_until_accepted():
    ref, cam, truth = simulated_pair([0, 0], [0, 3 * S], duration_ns=21 * S, seed=5)
    rng = np.random.default_rng(9)

    def featureless_first_window(times):
        start = times.min()
        later = times[times >= start + 10 * S]
        noise = start + np.concatenate([[0], rng.integers(0, 10 * S, 5_000)])
        return np.sort(np.concatenate([noise, later]))

    est = estimate_offset(featureless_first_window(ref), featureless_first_window(cam))
    assert not est.windows[0].accepted and est.windows[0].cost >= 1e-4
    assert est.accepted and est.window.index == 1
    assert abs(est.offset_ns - truth) <= TOL


def test_unrelated_streams_are_not_accepted_and_report_the_lowest_cost_window():
    rng = np.random.default_rng(11)
    ref = rng.integers(0, 25 * S, 3_000)
    cam = rng.integers(0, 25 * S, 3_000)
    est = estimate_offset(ref, cam)
    assert not est.accepted
    assert len(est.windows) == 2  # two whole 10 s windows in 25 s
    assert est.cost == min(w.cost for w in est.windows) >= 1e-4


def test_several_cameras_against_one_reference():
    rig = rigsim.default_rig(duration_ns=12 * S)
    streams = rigsim.simulate_streams(rig)
    ests = estimate_offsets(streams, reference=rig.reference_topic)
    truth = rig.true_offsets_ns()
    assert set(ests) == set(truth) - {rig.reference_topic}
    for topic, est in ests.items():
        assert est.accepted and abs(est.offset_ns - truth[topic]) <= TOL


@pytest.mark.parametrize(
    ('kwargs', 'match'),
    [
        ({'tau_ns': -1}, 'tau_ns'),
        ({'window_ns': 0}, 'window_ns'),
        ({'window_ns': 10 * S + 1}, 'whole number of bins'),
        ({'epsilon': float('nan')}, 'epsilon'),
        ({'epsilon': -1e-4}, 'epsilon'),
        ({'percentile': 0}, 'percentile'),
        ({'percentile': 100}, 'percentile'),
    ],
)
def test_bad_parameters_are_refused(kwargs, match):
    with pytest.raises(ParameterError, match=match):
        paper.PaperParams(**kwargs)


def test_empty_or_unknown_streams_are_refused_by_name():
    with pytest.raises(StreamError, match="'/cam1'.*no events"):
        estimate_offset(np.arange(10), np.array([], dtype=np.int64), cam_name='/cam1')
    with pytest.raises(StreamError, match="'/nope'"):
        estimate_offsets({'/a': np.arange(3)}, reference='/nope')
