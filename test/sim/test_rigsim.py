"""The simple rig simulator: its ground truth is what its clocks say."""

import numpy as np
import pytest

from evsync_ros.errors import ParameterError
from evsync_ros.sim import rigsim

S = 1_000_000_000


def test_true_offsets_follow_start_moments_and_clock_readings():
    rig = rigsim.SimRig(
        cameras=(rigsim.SimCamera('/a', start_ns=S, clock_at_start_ns=100 * S),
                 rigsim.SimCamera('/b', start_ns=3 * S, clock_at_start_ns=0)),
        duration_ns=6 * S,
    )
    # /a reads 100 s at world 1 s; /b reads 0 at world 3 s, when /a reads 102 s.
    assert rig.true_offsets_ns() == {'/a': 0, '/b': 102 * S}


def test_streams_start_on_each_clock_and_are_deterministic_by_seed():
    rig = rigsim.rig_from_start_delays([0, 2 * S], clocks_ns=[5 * S, 0], duration_ns=4 * S, seed=3)
    a = rigsim.simulate_streams(rig)
    b = rigsim.simulate_streams(rig)
    for topic, times in a.items():
        np.testing.assert_array_equal(times, b[topic])
        assert times.dtype == np.int64 and np.all(np.diff(times) >= 0)
    t0, t1 = (a[c.topic] for c in rig.cameras)
    assert 5 * S <= t0[0] < 5 * S + 10_000_000
    assert 0 <= t1[0] < 10_000_000
    # the later camera records 2 s less of the same 4 s
    assert t1[-1] - t1[0] == pytest.approx(t0[-1] - t0[0] - 2 * S, abs=0.05 * S)


def test_bad_rigs_are_refused():
    with pytest.raises(ParameterError, match='two cameras'):
        rigsim.SimRig(cameras=(rigsim.SimCamera('/a'),))
    with pytest.raises(ParameterError, match='distinct'):
        rigsim.SimRig(cameras=(rigsim.SimCamera('/a'), rigsim.SimCamera('/a')))
    with pytest.raises(ParameterError, match='start_ns'):
        rigsim.SimRig(cameras=(rigsim.SimCamera('/a'), rigsim.SimCamera('/b', start_ns=-1)))
