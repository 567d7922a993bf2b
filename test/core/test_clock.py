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


def test_a_correction_track_passes_through_its_samples_and_carries_the_lines_beyond():
    from evsync_ros.core.clock import CorrectionTrack
    own = np.array([10, 20, 30], np.int64) * 1_000_000_000
    rig = own + np.array([5_000_000, 5_000_300, 5_000_900])  # the offset grows: 0.03 then 0.06 ppm
    track = CorrectionTrack(own[::-1], rig[::-1], topic='/b')  # in any order
    for o, r in zip(own, rig):
        assert track.at(int(o)).apply_one(int(o)) == r
    mid = track.at(25 * 10**9)
    assert mid.skew_ppm == pytest.approx(0.06) and mid.apply_one(25 * 10**9) == 25 * 10**9 + 5_000_600
    assert track.at(0).apply_one(0) == 5_000_000 - 300  # before the first: the first line, back
    assert track.at(40 * 10**9).apply_one(40 * 10**9) == 40 * 10**9 + 5_001_500  # after the last: the last line


def test_a_correction_track_keeps_the_newest_report_of_an_instant_and_refuses_none():
    from evsync_ros.core.clock import CorrectionTrack
    from evsync_ros.errors import StreamError
    track = CorrectionTrack(np.array([5, 5]), np.array([105, 107]), topic='/b')
    assert len(track) == 1 and track.at(0) == ClockCorrection(offset_ns=102)
    with pytest.raises(StreamError, match='/b'):
        CorrectionTrack(np.array([], np.int64), np.array([], np.int64), topic='/b')
