import numpy as np
import pytest

from evsync_ros.core.density import as_times, bin_counts, event_density
from evsync_ros.errors import ParameterError, StreamError


def test_counts_per_bin_ignore_events_outside_the_window():
    t = np.array([-1, 0, 999, 1000, 2500, 2999, 3000, 10_000], dtype=np.int64)
    counts = bin_counts(t, start_ns=0, bin_ns=1000, n_bins=3)
    assert counts.tolist() == [2, 1, 2]


def test_density_is_normalised_by_the_window_total():
    t = np.array([5, 6, 7, 1005, 2005, 2006], dtype=np.int64) + 100
    m, total = event_density(t, start_ns=100, bin_ns=1000, n_bins=4)
    assert total == 6
    np.testing.assert_allclose(m, [3 / 6, 1 / 6, 2 / 6, 0.0])
    assert m.sum() == pytest.approx(1.0)


def test_empty_window_gives_zero_density_and_zero_total():
    m, total = event_density(np.array([50_000], dtype=np.int64), start_ns=0, bin_ns=1000, n_bins=10)
    assert total == 0 and not m.any()


@pytest.mark.parametrize('bad', [0, -5, 1.5, True])
def test_bin_width_must_be_a_positive_integer(bad):
    with pytest.raises(ParameterError, match='bin width'):
        bin_counts(np.zeros(3, dtype=np.int64), start_ns=0, bin_ns=bad, n_bins=3)


def test_stream_errors_name_the_stream():
    with pytest.raises(StreamError, match="'/cam1'"):
        as_times(np.zeros((2, 2), dtype=np.int64), name='/cam1')
    with pytest.raises(StreamError, match="'/cam2'.*integer"):
        as_times(np.array([0.5, 1.5]), name='/cam2')
