"""Binned streams: the same counts as the sorted array, in any chunking, and freed behind."""

import numpy as np
import pytest

from evsync_ros.core.bins import BLOCK_BINS, BinnedStream, SortedTimes
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.errors import ParameterError


def times(n=200_000, seed=0):
    rng = np.random.default_rng(seed)
    return np.sort(rng.integers(0, 30 * 10**9, n)) + 1_700_000_000 * 10**9


@pytest.mark.parametrize('chunk', [1, 977, 50_000, 10**9])
def test_counts_equal_the_sorted_arrays_in_any_chunking(chunk):
    t = times()
    b = BinnedStream(grid_ns=50_000)
    for i in range(0, t.size, chunk):
        b.add(t[i:i + chunk])
    whole = SortedTimes(t)
    assert b.origin_ns == t[0] and b.first_ns == t[0] and b.last_ns == t[-1] and b.events == t.size
    for start, bin_ns, n in [(t[0], 1_000_000, 30_000), (t[0] + 7 * 50_000, 50_000, 123_457),
                             (t[0] - 10**9, 1_000_000, 2000), (t[0] + 5 * 10**9, 20_000_000, 10)]:
        np.testing.assert_array_equal(b.counts(start, bin_ns, n), whole.counts(start, bin_ns, n))


def test_a_correction_is_applied_before_binning():
    t = times(20_000)
    c = ClockCorrection(offset_ns=5_000_000, skew_ppm=40.0, anchor_ns=int(t[0]))
    b = BinnedStream(grid_ns=50_000, correction=c)
    b.add(t)
    np.testing.assert_array_equal(b.counts(b.origin_ns, 1_000_000, 31_000),
                                  SortedTimes(c.apply(t)).counts(b.origin_ns, 1_000_000, 31_000))


def test_drop_frees_whole_blocks_and_counts_late_events():
    t = times()
    b = BinnedStream(grid_ns=50_000)
    b.add(t)
    full = b.nbytes
    b.drop_before(int(t[0]) + 20 * 10**9)
    assert 0 < b.nbytes < full / 2
    kept = int(np.sum(t >= t[0] + 10 * 10**9))  # a block is 3.3 s: some bins before 20 s stay
    assert b.counts(int(t[0]) + 20 * 10**9, 10**9, 10).sum() == np.sum(t >= t[0] + 20 * 10**9)
    b.add(t[:10])  # too late: their bins are gone
    assert b.dropped_late == 10 and b.events == t.size + 10 and kept > 0


def test_counts_off_the_grid_are_refused():
    b = BinnedStream(grid_ns=50_000, origin_ns=0)
    b.add(np.array([1, 2, 3], np.int64))
    with pytest.raises(ParameterError, match='grid'):
        b.counts(10_000, 50_000, 3)
    with pytest.raises(ParameterError, match='grid'):
        b.counts(0, 70_000, 3)
    assert BLOCK_BINS * 50_000 > 3 * 10**9


def test_sorted_times_answer_from_their_histogram_as_from_the_events():
    # repeated questions on one grid come from a histogram of the whole array, made once; a grid
    # too fine for one (HISTOGRAM_BINS) is answered from the events
    rng = np.random.default_rng(3)
    t = np.sort(rng.integers(10**15, 10**15 + 3 * 10**9, 50_000))
    cached = SortedTimes(t)
    for start, bin_ns, n in [(10**15 - 5_000_123, 1_000_000, 3100), (10**15 + 777, 100_000, 5000),
                             (10**15 + 2_900_000_777, 100_000, 4000), (10**15 - 10**9, 1, 1000)]:
        lo, hi = np.searchsorted(t, [start, start + n * bin_ns])
        direct = np.bincount((t[lo:hi] - start) // bin_ns, minlength=n)[:n]
        np.testing.assert_array_equal(cached.counts(start, bin_ns, n), direct)
        np.testing.assert_array_equal(cached.counts(start + 7 * bin_ns, bin_ns, n),  # the same grid, again
                                      np.bincount((t[(t >= start + 7 * bin_ns) & (t < start + (n + 7) * bin_ns)]
                                                   - start - 7 * bin_ns) // bin_ns, minlength=n)[:n])


@pytest.mark.parametrize('as_bins', [False, True], ids=['times', 'bins'])
def test_a_stream_of_small_chunks_is_followed_past_the_far_limit_and_a_corrupt_one_is_not(as_bins):
    # a quiet camera's 1 ms packets of a few events each, for longer than FAR_NS: every event binned
    # (its centre follows it); one small chunk a year away is still counted as far
    grid = 100_000
    b = BinnedStream(grid_ns=grid)
    rng = np.random.default_rng(0)
    t0 = 1_700_000_000_000_000_000

    def add(times):
        if not as_bins:
            b.add(times)
            return
        k, counts = np.unique(times // grid, return_counts=True)
        b.add_bins(k, counts, lo=int(times[0]), hi=int(times[-1]), mid=int(times[times.size // 2]))

    for ms in range(0, 130_000, 5):  # 130 s, a packet every 5 ms
        add(np.sort(t0 + ms * 1_000_000 + rng.integers(0, 1_000_000, 6)).astype(np.int64))
    assert b.far_events == 0 and b.events == 26_000 * 6
    add(np.array([t0 + 365 * 86_400 * 10**9] * 3, np.int64))
    assert b.far_events == 3
