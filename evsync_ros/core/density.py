"""Event density M(t): events per bin of width tau, normalised by the window total (paper eq. 2).

numpy only. Times are int64 nanoseconds on one camera's own timeline.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from evsync_ros.core.errors import ParameterError, StreamError

TimeArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
TIME_LIMIT_NS = 1 << 62
"""Event times are within this of zero (146 years; a ROS time holds 2^31 s, 68 years), so that the
difference of any two fits int64."""


def as_times(times: object, *, name: str) -> TimeArray:
    """Return ``times`` as a 1-D int64 array, or raise a StreamError naming the stream."""
    arr = np.asarray(times)
    if arr.ndim != 1:
        raise StreamError(f'stream {name!r}: event times must be 1-D, got shape {arr.shape}')
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise StreamError(f'stream {name!r}: event times must be integer nanoseconds, got {arr.dtype}')
    if arr.size and np.issubdtype(arr.dtype, np.unsignedinteger) and int(arr.max()) > TIME_LIMIT_NS:
        raise StreamError(f'stream {name!r}: an event time is later than any ROS time ({int(arr.max())} ns)')
    arr = arr.astype(np.int64, copy=False)
    if arr.size and (int(arr.min()) < -TIME_LIMIT_NS or int(arr.max()) > TIME_LIMIT_NS):
        raise StreamError(f'stream {name!r}: an event time is further from zero than any ROS time '
                          f'({int(arr.min())} to {int(arr.max())} ns)')
    return arr


def paired_offset_ns(*, ref_start_ns: int, cam_start_ns: int, bins_apart: Any, bin_ns: int) -> Any:
    """The offset (what is added to a camera's times to put them on the reference's timeline) that
    pairing reference bin ``i`` (counted from ``ref_start_ns``) with camera bin ``i - bins_apart``
    (from ``cam_start_ns``) stands for; ``bins_apart`` an int or an array of them. Every lag, shift
    and peak of either method becomes an offset here, so that the sign convention lives in one place."""
    return ref_start_ns - cam_start_ns + bins_apart * bin_ns


def check_positive_int(value: int, *, name: str) -> int:
    """Return ``value`` if it is a positive integer, else raise ParameterError."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
        raise ParameterError(f'{name} must be a positive integer, got {value!r}')
    return int(value)


def bin_counts(times: TimeArray, *, start_ns: int, bin_ns: int, n_bins: int) -> npt.NDArray[np.int64]:
    """Count events per bin [start + k*bin, start + (k+1)*bin), k = 0..n_bins-1; others are ignored."""
    check_positive_int(bin_ns, name='bin width')
    check_positive_int(n_bins, name='number of bins')
    rel = times - np.int64(start_ns)
    idx = rel // np.int64(bin_ns)
    idx = idx[(idx >= 0) & (idx < n_bins)]
    return np.bincount(idx, minlength=n_bins).astype(np.int64, copy=False)


def event_density(
    times: TimeArray, *, start_ns: int, bin_ns: int, n_bins: int
) -> tuple[FloatArray, int]:
    """Normalised density M and the window's event count N.

    M[k] = (events in bin k) / N, so M sums to 1 over the window; an empty window gives all
    zeros and N = 0 (the caller decides what an empty window means).
    """
    counts = bin_counts(times, start_ns=start_ns, bin_ns=bin_ns, n_bins=n_bins)
    total = int(counts.sum())
    if total == 0:
        return np.zeros(n_bins, dtype=np.float64), 0
    return counts / float(total), total
