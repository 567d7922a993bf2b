"""Event counts on a fixed grid, filled a chunk at a time and freed behind: the streaming form of a
camera's event times (``BinnedStream``), and the same question answered from a sorted array held
whole (``SortedTimes``). numpy only (docs/method.md, "Streaming")."""

from __future__ import annotations

import numpy as np

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.density import TIME_LIMIT_NS, FloatArray, TimeArray, check_positive_int
from evsync_ros.core.errors import ParameterError, StreamError

BLOCK_BINS = 1 << 16
"""Bins per block (6.6 s of the refined estimator's 100 us bins)."""
BLOCK_DTYPE = np.int32
_BLOCK_BYTES = BLOCK_BINS * np.dtype(BLOCK_DTYPE).itemsize
SPARSE_BINS = 4 * BLOCK_BINS
"""A chunk spanning more bins than this is binned block by block (memory follows its blocks)."""
FAR_NS = 60_000_000_000
"""An event this far from its chunk's median time (a chunk is one message) is a corrupt time: it is
counted in ``far_events`` and not binned, so that corrupt times cannot spread bins over years."""
MIN_CENTRE_EVENTS = 32
"""A chunk with fewer events is judged against the stream's last centre, not its own median."""
PENDING_EVENTS = 1 << 16
"""Event times a stream holds uncounted (512 kB): chunks are counted together, one bincount for many
messages, when their counts are read, bins are freed, or this many wait."""


def known(value: int | None, what: str) -> int:
    """``value``, which the caller knows to be set by now (a stream's origin once it has an event);
    StreamError naming ``what`` if it is not."""
    if value is None:
        raise StreamError(f'{what} is not known yet (no event)')
    return value


HISTOGRAM_BINS = 1 << 21
"""``SortedTimes`` keeps whole-array histograms of at most this many bins (8 MB each)."""
HISTOGRAMS = 4
"""... and at most this many (bin width and phase) at once, the newest."""


class SortedTimes:
    """Counts from a sorted int64 array held whole. Repeated questions on one grid (the windows of
    one camera) are answered from a histogram of the whole array on that grid, made once."""

    def __init__(self, times: TimeArray) -> None:
        self.times = times
        self._histograms: dict[tuple[int, int], tuple[int, np.ndarray]] = {}

    def counts(self, start_ns: int, bin_ns: int, n: int) -> FloatArray:
        hist = self._histogram(start_ns, bin_ns)
        if hist is None:
            lo, hi = np.searchsorted(self.times, [start_ns, start_ns + n * bin_ns])
            idx = (self.times[lo:hi] - start_ns) // bin_ns
            return np.bincount(idx, minlength=n)[:n].astype(np.float64)
        origin, h = hist
        i0 = (start_ns - origin) // bin_ns
        out = np.zeros(n)
        lo, hi = max(i0, 0), min(i0 + n, h.size)
        if hi > lo:
            out[lo - i0:hi - i0] = h[lo:hi]
        return out

    def _histogram(self, start_ns: int, bin_ns: int) -> tuple[int, np.ndarray] | None:
        """(origin, counts) of the whole array on the grid of ``bin_ns`` through ``start_ns``, or None
        when that grid would have too many bins."""
        key = (bin_ns, start_ns % bin_ns)
        found = self._histograms.get(key)
        if found is not None or self.times.size == 0:
            return found
        first, last = int(self.times[0]), int(self.times[-1])
        origin = first - (first - start_ns) % bin_ns
        if (last - origin) // bin_ns + 1 > HISTOGRAM_BINS:
            return None
        h = np.bincount((self.times - origin) // bin_ns).astype(np.int32)
        if len(self._histograms) >= HISTOGRAMS:
            del self._histograms[next(iter(self._histograms))]
        self._histograms[key] = (origin, h)
        return origin, h

    @property
    def first_ns(self) -> int:
        return int(self.times[0])

    @property
    def last_ns(self) -> int:
        return int(self.times[-1])


class _Grid:
    """Counts read from bins of ``grid_ns`` counted from ``origin_ns``; a subclass gives ``_fine``."""

    grid_ns: int
    origin_ns: int | None

    def counts(self, start_ns: int, bin_ns: int, n: int) -> FloatArray:
        """Events per bin [start + k bin, start + (k + 1) bin), k < n, as float64."""
        if self.origin_ns is None:
            return np.zeros(n)
        i0, k = self._grid_index(start_ns, bin_ns)
        fine = self._fine(i0, i0 + n * k)
        return (fine.reshape(n, k).sum(axis=1) if k > 1 else fine).astype(np.float64)

    def _grid_index(self, start_ns: int, bin_ns: int) -> tuple[int, int]:
        if self.origin_ns is None:
            raise ParameterError('counts of a stream whose grid is not placed yet (no event)')
        rel = start_ns - self.origin_ns
        if rel % self.grid_ns or bin_ns % self.grid_ns:
            raise ParameterError(f'counts from {start_ns} in bins of {bin_ns} ns are not on the {self.grid_ns} ns grid '
                                 f'from {self.origin_ns}')
        return rel // self.grid_ns, bin_ns // self.grid_ns

    def _fine(self, i0: int, i1: int) -> np.ndarray:
        raise NotImplementedError


class BinnedStream(_Grid):
    """A stream's event counts on a grid of ``grid_ns`` from ``origin_ns``, kept in blocks.

    ``correction`` (optional) is applied to every chunk before binning: a stream binned on a
    skew-corrected timeline. ``origin_ns`` defaults to the first (corrected) event added.

    A chunk's blocks, span and far events are settled as it is added; its times are counted into
    the blocks with later chunks' (``flush``), so that a message costs a few scalar steps rather
    than a bincount of its own. Whatever reads or frees the counts flushes first, and the blocks
    a chunk needs are made when it is added: the counts, ``nbytes`` and ``dropped_late`` are at
    every moment what binning each chunk at once would give.
    """

    def __init__(self, *, grid_ns: int, origin_ns: int | None = None,
                 correction: ClockCorrection | None = None) -> None:
        self.grid_ns = check_positive_int(grid_ns, name='grid_ns')
        self.origin_ns = origin_ns
        self.correction = correction if correction is not None and not correction.is_identity else None
        self._blocks: dict[int, np.ndarray] = {}
        self._pending: list[TimeArray] = []
        """Chunks added and not yet counted, each within SPARSE_BINS of its least bin."""
        self._pending_bins = (0, 0)
        """The least and greatest bin of the pending chunks."""
        self._pending_events = 0
        self.first_ns: int | None = None
        """Earliest (corrected) event time seen."""
        self.last_ns: int | None = None
        """Latest (corrected) event time seen."""
        self.events = 0
        self._dropped_late = 0
        self.far_events = 0
        """Events far from the rest of their chunk, or beyond any ROS time (counted, not binned)."""
        self._floor_block: int | None = None
        self._centre: int | None = None
        """A time of the last chunk large enough to trust (its median, or any of its times when it spans
        no more than FAR_NS), or of the last small one wholly near it: what a small chunk is judged
        against (``near``), so that a stream of small chunks (a quiet camera's 1 ms packets) carries
        it along."""

    def add(self, times: TimeArray, *, lo: int | None = None, hi: int | None = None) -> None:
        """Bin a chunk of event times (any order); far times are counted instead (``FAR_NS``).
        ``lo``, ``hi``: the chunk's least and greatest time when the caller has them (uncorrected)."""
        if times.size == 0:
            return
        given = times
        self.events += int(times.size)
        if self.correction is not None:
            times = self.correction.apply(times)
            lo = hi = None
        n = times.size
        near = self.near(times, update=True, lo=lo, hi=hi)
        if near is not times:
            self.far_events += n - near.size
            times, lo, hi = near, None, None
            if times.size == 0:
                return
        if lo is None or hi is None:
            lo, hi = int(times.min()), int(times.max())
        if self.origin_ns is None:
            self.origin_ns = lo
        self.first_ns = lo if self.first_ns is None else min(self.first_ns, lo)
        self.last_ns = hi if self.last_ns is None else max(self.last_ns, hi)
        i0 = (lo - self.origin_ns) // self.grid_ns
        i1 = (hi - self.origin_ns) // self.grid_ns
        if i1 - i0 > SPARSE_BINS:  # far-apart times (a clock jump, a corrupt time): bin per block, now
            self._add_per_block((times - np.int64(self.origin_ns)) // np.int64(self.grid_ns))
            return
        self._hold(times.copy() if times is given else times, i0, i1)  # the caller's array may change

    def _hold(self, times: TimeArray, i0: int, i1: int) -> None:
        """Keep a compact chunk (bins ``i0`` to ``i1``) to count with the next: its blocks are made
        now (those already freed excepted), as binning it now would."""
        floor = self._floor_block
        for b in range(i0 // BLOCK_BINS, i1 // BLOCK_BINS + 1):
            if b not in self._blocks and (floor is None or b >= floor):
                self._blocks[b] = np.zeros(BLOCK_BINS, BLOCK_DTYPE)
        if self._pending:
            lo, hi = self._pending_bins
            self._pending_bins = (min(lo, i0), max(hi, i1))
        else:
            self._pending_bins = (i0, i1)
        self._pending.append(times)
        self._pending_events += times.size
        if self._pending_events >= PENDING_EVENTS:
            self.flush()

    def flush(self) -> None:
        """Count the chunks held into the blocks (``BinnedStream``: the counts do not depend on when)."""
        if not self._pending:
            return
        parts, (lo, hi) = self._pending, self._pending_bins
        self._pending, self._pending_events = [], 0
        times = parts[0] if len(parts) == 1 else np.concatenate(parts)
        idx = (times - np.int64(known(self.origin_ns, "a held chunk's origin"))) // np.int64(self.grid_ns)
        if hi - lo > SPARSE_BINS:  # chunks far apart from each other
            self._add_per_block(idx)
            return
        self._add_dense(np.bincount(idx - lo), lo, make=False)

    def _add_per_block(self, idx: np.ndarray) -> None:
        """Count bins ``idx`` block by block (far-apart bins: memory follows the blocks they are in)."""
        for b in np.unique(idx // BLOCK_BINS).tolist():
            part = idx[(idx >= b * BLOCK_BINS) & (idx < (b + 1) * BLOCK_BINS)]
            self._add_block_range(part - int(part.min()), int(part.min()))

    @property
    def dropped_late(self) -> int:
        """Events that arrived for bins already freed (counted, not binned)."""
        self.flush()
        return self._dropped_late

    def near(self, times: TimeArray, *, update: bool = False, lo: int | None = None, hi: int | None = None
             ) -> TimeArray:
        """``times`` without the far ones (``times`` itself when none is): those over ``FAR_NS`` from
        the chunk's median, or from the stream's last centre when the chunk is too small for its median
        to be trusted (a few corrupt times can make it); ``update``: the chunk's median becomes the
        centre. ``lo``, ``hi``: the chunk's least and greatest time, when known."""
        if lo is None or hi is None:
            lo, hi = int(times.min()), int(times.max())
        centre = self._centre
        trusted = times.size >= MIN_CENTRE_EVENTS or centre is None
        if trusted and hi - lo <= FAR_NS and lo >= -TIME_LIMIT_NS and hi <= TIME_LIMIT_NS:
            if update:  # a compact chunk (every message but a corrupt one): no median needed on this hot path
                self._centre = int(times[times.size // 2])
            return times
        if trusted or centre is None:
            centre = int(np.partition(times, times.size // 2)[times.size // 2])
            if update:
                self._centre = centre
        if lo >= centre - FAR_NS and hi <= centre + FAR_NS and lo >= -TIME_LIMIT_NS and hi <= TIME_LIMIT_NS:
            if update:  # a small chunk wholly near the centre: the stream goes on, and its centre with it
                self._centre = int(times[times.size // 2])
            return times
        near = (times >= max(centre - FAR_NS, -TIME_LIMIT_NS)) & (times <= min(centre + FAR_NS, TIME_LIMIT_NS))
        return times[near]

    def add_counts(self, k0: int, counts: np.ndarray, *, n: int, lo: int, hi: int, mid: int) -> bool:
        """``add`` of a chunk of ``n`` times (least ``lo``, greatest ``hi``, middle ``mid``) already
        counted on the grid (bins ``k0``, ``k0 + 1`` ... from time 0 in ``counts``), where ``add`` would
        bin every one of them (no correction, an origin on the grid, none far); False, nothing
        done, otherwise (``add`` the times)."""
        g, origin, centre = self.grid_ns, self.origin_ns, self._centre
        near = n >= MIN_CENTRE_EVENTS or centre is None or (centre - FAR_NS <= lo and hi <= centre + FAR_NS)
        if (self.correction is not None or origin is None or origin % g or counts.size > SPARSE_BINS or not near
                or hi - lo > FAR_NS or lo < -TIME_LIMIT_NS or hi > TIME_LIMIT_NS):
            return False
        self._centre = mid
        self.events += n
        self.first_ns = lo if self.first_ns is None else min(self.first_ns, lo)
        self.last_ns = hi if self.last_ns is None else max(self.last_ns, hi)
        i0 = k0 - origin // g
        b, at = divmod(i0, BLOCK_BINS)
        block = self._blocks.get(b)
        if block is not None and at + counts.size <= BLOCK_BINS and counts.dtype == BLOCK_DTYPE:
            block[at:at + counts.size] += counts  # within one block made already (every message but a few)
        else:
            self._add_dense(counts, i0)
        return True

    def add_bins(self, bins: np.ndarray, counts: np.ndarray, *, lo: int, hi: int, mid: int) -> None:
        """Add counts already made on the stream's grid (``bins``: ascending distinct indices k, bin k
        holding the times in [k*grid_ns, (k+1)*grid_ns); ``counts``: events in each), the form a camera
        process sends its estimator (``core.counts``). ``lo``, ``hi``, ``mid``: the chunk's least,
        greatest and middle event time. As ``add``: far bins are counted instead (judged by their
        start). Needs an origin on the grid (or none yet) and no correction (StreamError otherwise)."""
        n = int(counts.sum())
        if n == 0:
            return
        if self.correction is not None:
            raise StreamError('a stream binned on a corrected timeline takes event times, not bins')
        if self.origin_ns is not None and self.origin_ns % self.grid_ns:
            raise StreamError(f'bins need an origin on the {self.grid_ns} ns grid, got {self.origin_ns}')
        self.events += n
        centre = self._centre
        trusted = n >= MIN_CENTRE_EVENTS or centre is None
        if trusted and hi - lo <= FAR_NS and lo >= -TIME_LIMIT_NS and hi <= TIME_LIMIT_NS:
            self._centre = mid
        else:
            starts = bins * self.grid_ns
            if trusted or centre is None:  # the weighted median of the bins
                centre = int(starts[int(np.searchsorted(np.cumsum(counts), (n + 1) // 2))])
                self._centre = centre
            keep = (starts >= max(centre - FAR_NS, -TIME_LIMIT_NS)) & (starts <= min(centre + FAR_NS, TIME_LIMIT_NS))
            if keep.all():  # a small chunk wholly near the centre: the stream goes on, and its centre with it
                self._centre = mid
            else:
                self.far_events += int(counts[~keep].sum())
                bins, counts = bins[keep], counts[keep]
                if bins.size == 0:
                    return
                lo = max(lo, int(bins[0]) * self.grid_ns)
                hi = min(hi, int(bins[-1] + 1) * self.grid_ns - 1)
        if self.origin_ns is None:
            self.origin_ns = int(bins[0]) * self.grid_ns
        self.first_ns = lo if self.first_ns is None else min(self.first_ns, lo)
        self.last_ns = hi if self.last_ns is None else max(self.last_ns, hi)
        idx = bins - np.int64(self.origin_ns // self.grid_ns)
        i0 = int(idx[0])
        if int(idx[-1]) - i0 > SPARSE_BINS:  # far-apart bins: block by block
            for b in np.unique(idx // BLOCK_BINS).tolist():
                part = (idx >= b * BLOCK_BINS) & (idx < (b + 1) * BLOCK_BINS)
                self._add_sparse(idx[part], counts[part])
            return
        self._add_sparse(idx, counts)

    def _add_sparse(self, idx: np.ndarray, counts: np.ndarray) -> None:
        i0 = int(idx[0])
        dense = np.zeros(int(idx[-1]) - i0 + 1, np.int64)
        dense[idx - i0] = counts
        self._add_dense(dense, i0)

    def _add_block_range(self, rel: np.ndarray, i0: int) -> None:
        """Count bins ``i0 + rel`` (rel >= 0)."""
        self._add_dense(np.bincount(rel), i0)

    def _add_dense(self, counts: np.ndarray, i0: int, *, make: bool = True) -> None:
        """Add ``counts`` to bins ``i0``, ``i0 + 1`` ... (``make``: making the blocks they need; else
        the blocks not there have no counts: held chunks made theirs, and the gaps between hold none)."""
        b0, b1 = i0 // BLOCK_BINS, (i0 + counts.size - 1) // BLOCK_BINS
        for b in range(b0, b1 + 1):
            s = max(i0, b * BLOCK_BINS)
            e = min(i0 + counts.size, (b + 1) * BLOCK_BINS)
            part = counts[s - i0:e - i0]
            if self._floor_block is not None and b < self._floor_block:
                self._dropped_late += int(part.sum())
                continue
            block = self._blocks.get(b)
            if block is None:
                if not make:
                    continue
                block = self._blocks[b] = np.zeros(BLOCK_BINS, BLOCK_DTYPE)
            block[s - b * BLOCK_BINS:e - b * BLOCK_BINS] += part.astype(BLOCK_DTYPE)

    def _fine(self, i0: int, i1: int) -> np.ndarray:
        self.flush()
        fine = np.zeros(i1 - i0, np.int64)
        for b in range(i0 // BLOCK_BINS, (i1 - 1) // BLOCK_BINS + 1):
            block = self._blocks.get(b)
            if block is None:
                continue
            s, e = max(i0, b * BLOCK_BINS), min(i1, (b + 1) * BLOCK_BINS)
            fine[s - i0:e - i0] = block[s - b * BLOCK_BINS:e - b * BLOCK_BINS]
        return fine

    def next_event_ns(self, t_ns: int) -> int | None:
        """Start of the first grid bin ending after ``t_ns`` that holds an event (None: none held), so
        that callers step over spans with no events (a camera's clock jump) instead of walking them."""
        if self.origin_ns is None:
            return None
        self.flush()
        i = (t_ns - self.origin_ns) // self.grid_ns
        for b in sorted(b for b in self._blocks if b >= i // BLOCK_BINS):
            s = max(i - b * BLOCK_BINS, 0)
            # a busy stream has an event within the first few bins: look there before the whole block
            # (the stream estimator asks this once per message)
            for lo, hi in ((s, s + 256), (s + 256, BLOCK_BINS)):
                nz = np.flatnonzero(self._blocks[b][lo:hi])
                if nz.size:
                    return self.origin_ns + (b * BLOCK_BINS + lo + int(nz[0])) * self.grid_ns
        return None

    def snapshot(self, start_ns: int, end_ns: int) -> GridCounts:
        """A copy of the grid bins over [start_ns, end_ns) (start on the grid): counts to read
        while this stream goes on filling (another thread, the live node)."""
        if self.origin_ns is None:
            return GridCounts(grid_ns=self.grid_ns, start_ns=start_ns, fine=np.zeros(0, np.int64))
        i0, _ = self._grid_index(start_ns, self.grid_ns)
        n = max(0, -(-(end_ns - start_ns) // self.grid_ns))
        return GridCounts(grid_ns=self.grid_ns, start_ns=start_ns, fine=self._fine(i0, i0 + n),
                          first_ns=self.first_ns, last_ns=self.last_ns)

    def drop_before(self, t_ns: int) -> None:
        """Free every block that ends before ``t_ns``; later events for them are counted as late."""
        if self.origin_ns is None:
            return
        floor = ((t_ns - self.origin_ns) // self.grid_ns) // BLOCK_BINS
        if self._floor_block is not None and floor <= self._floor_block:
            return
        self.flush()  # what is held was added before the floor rose
        self._floor_block = floor
        for b in [b for b in self._blocks if b < floor]:
            del self._blocks[b]

    @property
    def held_from_ns(self) -> int | None:
        """Where the bins still held begin (None: none freed yet): counts before it are gone."""
        if self.origin_ns is None or self._floor_block is None:
            return None
        return self.origin_ns + self._floor_block * BLOCK_BINS * self.grid_ns

    @property
    def nbytes(self) -> int:
        return len(self._blocks) * _BLOCK_BYTES

    @staticmethod
    def ceiling_bytes(span_ns: int, grid_ns: int) -> int:
        """The most a stream holds whose events all lie within ``span_ns``: whole blocks, one more
        for a span that does not start on a block's edge."""
        block_ns = BLOCK_BINS * grid_ns
        return (-(-span_ns // block_ns) + 1) * _BLOCK_BYTES


class GridCounts(_Grid):
    """Counts on a grid over one span, held whole (``BinnedStream.snapshot``); zero outside it."""

    def __init__(self, *, grid_ns: int, start_ns: int, fine: np.ndarray, first_ns: int | None = None,
                 last_ns: int | None = None) -> None:
        self.grid_ns = grid_ns
        self.origin_ns = start_ns
        self.fine = fine
        self.first_ns = first_ns
        """The stream's first and last event times when the snapshot was taken (where it has data)."""
        self.last_ns = last_ns

    def _fine(self, i0: int, i1: int) -> np.ndarray:
        out = np.zeros(i1 - i0, np.int64)
        s, e = max(i0, 0), min(i1, self.fine.size)
        if e > s:
            out[s - i0:e - i0] = self.fine[s:e]
        return out
