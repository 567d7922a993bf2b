"""A message's events as counts on the estimator's grid: what a camera process (one per camera, the
node's ``processes: per_camera``) sends the estimator process instead of every event time, and its
wire form, a flat int64 array. numpy only.

A 1 ms message of 1,250 events on the refined method's 100 us grid is about ten (bin, count) pairs:
the estimator gets what ``OnlineSync.add`` would take from the events (the arrival time, the middle,
least and greatest event time, the counts) at a hundredth of the bytes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from evsync_ros.core.density import TimeArray, check_positive_int
from evsync_ros.core.errors import StreamError

WIRE_VERSION = 1
NONE = np.iinfo(np.int64).min
"""A missing time in the wire form (no host pair)."""
_FIXED = 7
"""Fields of a record before its bins: receipt, mid, lo, hi, host event, host time, bins."""


@dataclass(frozen=True)
class MessageBins:
    """One message's events, counted on the grid (``bins``: ascending distinct indices k of
    [k*grid, (k+1)*grid); ``counts``: events in each). A message with no events has no bins and
    still says when it arrived (silence is judged by arrivals)."""

    receipt_ns: int
    mid_ns: int
    """The message's middle event time (its arrival lag is judged from it, as ``OnlineSync.add`` does)."""
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
        if hi // grid - k0 < 1 << 20:  # a compact message (every one but a corrupt one): one bincount
            dense = np.bincount(times // np.int64(grid) - np.int64(k0))
            bins = np.flatnonzero(dense)
            counts = dense[bins].astype(np.int64)
            bins = bins.astype(np.int64) + np.int64(k0)
        else:
            bins, c = np.unique(times // np.int64(grid), return_counts=True)
            counts = c.astype(np.int64)
        return cls(receipt_ns, int(times[times.size // 2]), lo, hi, bins.astype(np.int64), counts,
                   host_event_ns, host_ns)


def pack(messages: list[MessageBins], *, camera: int) -> np.ndarray:
    """The wire form of a batch of one camera's messages (``camera``: its index in ``topics``):
    [version, camera, n, then per message receipt, mid, lo, hi, host event, host time, k, k bins,
    k counts]."""
    parts: list[np.ndarray] = [np.array([WIRE_VERSION, camera, len(messages)], np.int64)]
    for m in messages:
        head = [m.receipt_ns, m.mid_ns, m.lo_ns, m.hi_ns,
                NONE if m.host_event_ns is None else m.host_event_ns, NONE if m.host_ns is None else m.host_ns,
                m.bins.size]
        parts += [np.array(head, np.int64), m.bins, m.counts]
    return np.concatenate(parts)


def unpack(data: np.ndarray, *, source: str) -> tuple[int, list[MessageBins]]:
    """(camera index, messages) of a batch in wire form; StreamError naming ``source`` when it is
    not one (another version, truncated, bins not ascending, negative counts)."""
    data = np.asarray(data, np.int64)

    def bad(why: str) -> StreamError:
        return StreamError(f'{source}: not an evsync counts batch: {why}')

    if data.size < 3 or int(data[0]) != WIRE_VERSION:
        raise bad(f'version {int(data[0]) if data.size else None}, expected {WIRE_VERSION}')
    camera, n = int(data[1]), int(data[2])
    if n < 0:
        raise bad(f'{n} messages')
    out: list[MessageBins] = []
    i = 3
    for j in range(n):
        if i + _FIXED > data.size:
            raise bad(f'message {j} truncated')
        receipt, mid, lo, hi, host_event, host, k = (int(x) for x in data[i:i + _FIXED])
        i += _FIXED
        if k < 0 or i + 2 * k > data.size:
            raise bad(f'message {j}: {k} bins')
        bins, counts = data[i:i + k].copy(), data[i + k:i + 2 * k].copy()
        i += 2 * k
        if k and (np.any(np.diff(bins) <= 0) or np.any(counts <= 0)):
            raise bad(f'message {j}: bins not ascending or counts not positive')
        out.append(MessageBins(receipt, mid, lo, hi, bins, counts, None if host_event == NONE else host_event,
                               None if host == NONE else host))
    if i != data.size:
        raise bad(f'{data.size - i} values after the last message')
    return camera, out
