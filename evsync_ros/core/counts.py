"""A message's events as counts on the estimator's grid: what a camera process (one per camera, the
node's ``processes: per_camera``) sends the estimator process instead of every event time, and its
wire form, a flat int64 array. numpy only.

A 1 ms message of 1,250 events on the refined method's 100 us grid is about ten (bin, count) pairs:
the estimator gets what ``Engine.add`` would take from the events (the arrival time, the middle,
least and greatest event time, the counts) at a hundredth of the bytes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from evsync_ros.core.density import TimeArray, check_positive_int


@dataclass(frozen=True)
class MessageBins:
    """One message's events, counted on the grid (``bins``: ascending distinct indices k of
    [k*grid, (k+1)*grid); ``counts``: events in each). A message with no events has no bins and
    still says when it arrived (silence is judged by arrivals)."""

    receipt_ns: int
    mid_ns: int
    """The message's middle event time (its arrival lag is judged from it, as ``Engine.add`` does)."""
    lo_ns: int
    hi_ns: int
    bins: np.ndarray
    counts: np.ndarray
    host_event_ns: int | None = None
    """``reference: host``: one of the message's event times, and"""
    host_ns: int | None = None
    """when the host had it (what ``HostTracker.add`` takes)."""

    @property
    def events(self) -> int:
        return int(self.counts.sum())

    @classmethod
    def of(cls, times: TimeArray, *, receipt_ns: int, grid_ns: int, host_event_ns: int | None = None,
           host_ns: int | None = None) -> MessageBins:
        """Count a message's event times (any order) on the grid of ``grid_ns`` from time 0."""
        grid = check_positive_int(grid_ns, name='grid_ns')
        if times.size == 0:
            empty = np.zeros(0, np.int64)
            return cls(receipt_ns, 0, 0, 0, empty, empty, host_event_ns, host_ns)
        lo, hi = int(times.min()), int(times.max())
        k0 = lo // grid
        mid = int(times[times.size // 2])
        if hi // grid - k0 < 1 << 20:  # a compact message (every one but a corrupt one): one bincount
            dense = np.bincount(times // np.int64(grid) - np.int64(k0))
            return cls.of_dense(dense, k0, receipt_ns=receipt_ns, mid_ns=mid, lo_ns=lo, hi_ns=hi,
                                host_event_ns=host_event_ns, host_ns=host_ns)
        bins, c = np.unique(times // np.int64(grid), return_counts=True)
        return cls(receipt_ns, mid, lo, hi, bins.astype(np.int64), c.astype(np.int64), host_event_ns, host_ns)

    @classmethod
    def of_dense(cls, dense: np.ndarray, k0: int, *, receipt_ns: int, mid_ns: int, lo_ns: int, hi_ns: int,
                 host_event_ns: int | None = None, host_ns: int | None = None) -> MessageBins:
        """A message counted already, in grid bins ``k0``, ``k0 + 1`` ... (``dense``, its empty bins
        among them: a live message's one C call gives them so)."""
        bins = np.flatnonzero(dense)
        return cls(receipt_ns, mid_ns, lo_ns, hi_ns, bins.astype(np.int64) + np.int64(k0),
                   dense[bins].astype(np.int64), host_event_ns, host_ns)
