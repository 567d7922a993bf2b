"""ClockCorrection: the offset-and-skew contract and its inverse."""

import numpy as np
import pytest

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.errors import ParameterError


def test_offset_and_skew_follow_the_contract():
    c = ClockCorrection(offset_ns=1_000, skew_ppm=50.0, anchor_ns=10 * 10**9)
    t = np.array([10 * 10**9, 12 * 10**9, 8 * 10**9], np.int64)
    # t + offset + skew * 1e-6 * (t - anchor): 2 s from the anchor at 50 ppm is 100 us.
    assert c.apply(t).tolist() == [10 * 10**9 + 1_000, 12 * 10**9 + 1_000 + 100_000, 8 * 10**9 + 1_000 - 100_000]
    assert [c.apply_one(v) for v in t.tolist()] == c.apply(t).tolist()


def test_inverse_undoes_offset_exactly_and_skew_to_a_nanosecond():
    t = np.arange(0, 100 * 10**9, 7_777_777_777, dtype=np.int64) + 1_600_000_000 * 10**9
    pure = ClockCorrection(offset_ns=-123_456_789)
    np.testing.assert_array_equal(pure.inverse().apply(pure.apply(t)), t)
    skewed = ClockCorrection(offset_ns=5_000_000, skew_ppm=-80.0, anchor_ns=int(t[3]))
    assert np.abs(skewed.inverse().apply(skewed.apply(t)) - t).max() <= 1


@pytest.mark.parametrize('kwargs', [{'offset_ns': 1.5}, {'skew_ppm': float('nan')}, {'skew_ppm': 1e6},
                                    {'anchor_ns': '3'}, {'offset_ns': True}])
def test_bad_corrections_are_refused(kwargs):
    with pytest.raises(ParameterError):
        ClockCorrection(**kwargs)
