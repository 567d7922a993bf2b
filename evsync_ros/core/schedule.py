"""Where windows go, and where a stream has data: one scheduler for the array, bag and live paths.

numpy only. Windows tile the reference's span with no overlap, all of one length chosen from the
span: long recordings get the longest windows (``window_ns``), short ones shorter windows so that
they still give several (``windows_wanted``), never shorter than ``min_window_ns``. The lengths
come from a 1-2-5 ladder so that a growing span (the live node) changes the grid only a few times;
a span known whole (offline) stretches them so that the windows fill it.

A stream *covers* a bin when the bin lies between its first and last event and not inside a run
of empty bins of ``gap_ns`` or more (a camera that started late, stopped early, paused or dropped
out). Correlations pair only covered bins (``refined``), so that an empty stretch or an edge is
never read as the scene going still.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from evsync_ros.core.errors import ParameterError

LADDER_S = (0.25, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 60.0)
"""Window lengths a plan chooses from (s), capped by ``window_ns``."""


def window_length_ns(span_ns: int, *, window_ns: int, min_window_ns: int, windows_wanted: int, tau_ns: int,
                     tile: bool = False) -> int:
    """The window length for a span: the longest ladder length (and at most ``window_ns``) that
    gives ``windows_wanted`` windows, and at least ``min_window_ns``; a whole number of ``tau_ns``.
    With ``tile`` (a span known whole, offline), the length is then stretched so that as many whole
    windows fill the span, rather than leave up to a window of it unused (never beyond ``window_ns``
    unless the span is shorter than one window).

    Raises:
        ParameterError: ``min_window_ns`` above ``window_ns``, or a length not a multiple of tau.
    """
    if min_window_ns > window_ns:
        raise ParameterError(f'min_window_ns ({min_window_ns}) must not exceed window_ns ({window_ns})')
    target = span_ns / max(1, windows_wanted)
    ladder = sorted({int(round(s * 1e9)) for s in LADDER_S if min_window_ns <= s * 1e9 <= window_ns}
                    | {min_window_ns, window_ns})
    length = max([v for v in ladder if v <= target] or [min_window_ns])
    if tile and span_ns >= length:
        count = span_ns // length
        stretched = span_ns // count // tau_ns * tau_ns
        if stretched <= window_ns:
            length = stretched
        else:  # the span holds more than whole windows of window_ns: as many of them, one more
            length = span_ns // (count + 1) // tau_ns * tau_ns if count * length < span_ns else length
    if length % tau_ns:
        raise ParameterError(f'window length {length} ns is not a whole number of tau ({tau_ns} ns)')
    return length


def plan(first_ns: int, last_ns: int, length_ns: int) -> list[int]:
    """Starts of the whole windows of ``length_ns`` that tile [first_ns, last_ns] from first_ns."""
    count = (last_ns - first_ns + 1) // length_ns
    return [first_ns + k * length_ns for k in range(max(0, count))]


def coverage(counts: npt.NDArray[np.float64], *, start_ns: int, bin_ns: int, first_ns: int | None,
             last_ns: int | None, gap_ns: int) -> npt.NDArray[np.bool_]:
    """Which of ``counts`` (bins of ``bin_ns`` from ``start_ns``) the stream covers (module notes):
    within [first_ns, last_ns] (None: no bound known on that side) and outside every run of at least
    ``gap_ns`` of empty bins."""
    n = counts.size
    lo = 0 if first_ns is None or first_ns <= start_ns else (first_ns - start_ns) // bin_ns
    hi = n if last_ns is None else min(n, (last_ns - start_ns) // bin_ns + 1)
    mask = np.zeros(n, dtype=bool)
    if hi > lo:
        mask[lo:hi] = True
    run = max(1, -(-gap_ns // bin_ns))
    empty = counts == 0
    if run <= n and empty.any():
        edges = np.diff(np.concatenate(([0], empty.view(np.int8), [0])))
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        for s, e in zip(starts[ends - starts >= run].tolist(), ends[ends - starts >= run].tolist()):
            mask[s:e] = False
    return mask
