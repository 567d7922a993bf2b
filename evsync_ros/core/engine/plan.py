"""Where a camera's windows go: one plan for the rig, offline and live. numpy only.

Windows tile the reference's events from its first one (after its last silence or restart), on one
grid whatever the camera's prior (windows that shifted with it would share data, and agree by it).
Their length comes from the span both streams have had since they (re)started, on the reference's
own clock (``schedule.window_length_ns``, its 1-2-5 ladder): it grows with the recording, and starts
short again after a jump. A window is fitted once the camera's data reach past it by the search's
reach; at the end of a recording (``ended``) once they reach it.

The paper's method has its own plan, the paper's loop: windows of T, one after the other, from where
both streams begin, until one is accepted (``paper_jobs``), on every path.
"""

from __future__ import annotations

from collections.abc import Container

from evsync_ros.core.bins import BinnedStream, GridCounts
from evsync_ros.core.engine.params import EngineParams
from evsync_ros.core.schedule import plan

__all__ = ['Window', 'from_start', 'job', 'paper_job', 'paper_jobs', 'stretch_jobs', 'window_jobs']

Window = tuple[GridCounts, GridCounts, int, int, int]
"""(reference counts, camera counts, window start, length, prior): one window to fit."""


def window_jobs(p: EngineParams, ref: BinnedStream, cam: BinnedStream, *, ref_since: int | None,
                cam_since: int | None, prior: int, restart: int | None, resumed: bool,
                fitted: Container[tuple[int, int]], ended: bool) -> list[Window]:
    """The refined method: the camera's windows whose data are complete, whose bins are held, and that
    have not been fitted (module notes); ``resumed``: the camera's events since ``cam_since`` follow a
    silence or a restart."""
    ref_last, cam_last, origin = ref.last_ns, cam.last_ns, ref.origin_ns
    if ref_last is None or cam_last is None or origin is None or ref_since is None or cam_since is None:
        return []
    g = p.grid_ns
    since = ref_since + -(ref_since - origin) % g
    reach = p.reach_ns
    begun = max(since, cam_since + prior, restart if restart is not None else since)  # short again after a step
    length = p.refined.window_length(ref_last - begun, tile=False)
    if length % g:
        return []
    newest = min(ref_last, cam_last + prior - (0 if ended else reach))
    # a window may begin before the camera's very first event by what it can spare and still pair
    # ``min_overlap`` of its bins (a camera a few ms later than the reference keeps its first window),
    # never before its return from a silence or a restart (no window spans the stream's gap)
    spare = 0 if resumed else int(length * (1 - p.refined.min_overlap))
    floor = max(since, cam_since + prior - spare, restart if restart is not None else since)
    if ref.held_from_ns is not None:  # bins freed: only a window placed anew could want them, and they are gone
        floor = max(floor, ref.held_from_ns)
    if cam.held_from_ns is not None:
        floor = max(floor, cam.held_from_ns + prior + reach)
    first = since + -(-(floor - since) // length) * length  # on the windows' grid
    return [job(p, ref, cam, w, length, prior) for w in _starts(ref, first, newest, length)
            if (w, length) not in fitted]


def from_start(p: EngineParams, ref: BinnedStream, cam: BinnedStream, *, ref_since: int, prior: int) -> Window:
    """A recording shorter than one whole window: its one window, from the reference's start (on the grid)."""
    length = p.refined.window_length(0)
    w = ref_since + -(ref_since - (ref.origin_ns or 0)) % p.grid_ns
    return job(p, ref, cam, w, length, prior)


def stretch_jobs(p: EngineParams, ref: BinnedStream, cam: BinnedStream, span: tuple[int, int], *, prior: int,
                 longer_ns: int) -> list[Window]:
    """The windows of ``span`` (reference timeline) planned as for a recording of its length (what
    ``evsync estimate --start --duration`` would do), while its bins are held; none when they would be
    no shorter than ``longer_ns`` (the decision's: only shorter windows add evidence), too few or too
    many."""
    start, end = span
    length = p.refined.window_length(end - start, tile=False)
    starts = range(start, end - length + 1, length)
    if (ref.first_ns is None or ref.first_ns > start or length % p.grid_ns
            or not p.refined.min_agreeing <= len(starts) <= 4 * p.refined.windows_wanted or length >= longer_ns):
        return []
    return [job(p, ref, cam, w, length, prior) for w in starts]


def job(p: EngineParams, ref: BinnedStream, cam: BinnedStream, w: int, length: int, prior: int) -> Window:
    """One window's job: the reference's counts over [w, w + length), the camera's over that span
    moved by ``prior`` and widened by the search's reach (and two grid bins) either side."""
    reach, g = p.reach_ns, p.grid_ns
    return (ref.snapshot(w, w + length), cam.snapshot(w - prior - reach - 2 * g, w - prior + length + reach + 2 * g),
            w, length, prior)


MAX_PLAN = 10_000
"""More windows than this between a camera's first and newest (27 hours of 10 s windows): the span
is mostly empty (a clock jump, corrupt times years apart), and only windows holding a reference event
are planned, found by stepping over the empty bins rather than walking them."""


def _starts(ref: BinnedStream, first: int, newest: int, length: int) -> list[int]:
    """Starts of the whole windows of ``length`` from ``first`` to ``newest`` (``schedule.plan``), only
    those holding a reference event where there would be more than ``MAX_PLAN``."""
    if (newest - first + 1) // length <= MAX_PLAN:
        return plan(first, newest, length)
    out: list[int] = []
    w = first
    while w + length <= newest + 1 and len(out) <= MAX_PLAN:
        nxt = ref.next_event_ns(w)
        if nxt is None:
            break
        if nxt >= w + length:
            w = first + (nxt - first) // length * length
            continue
        out.append(w)
        w += length
    return out


def paper_jobs(p: EngineParams, ref: BinnedStream, cam: BinnedStream, *, origin: int, prior: int,
               k: int) -> tuple[list[tuple[int, Window]], int]:
    """The paper's loop: its windows k, k + 1, ... of T from ``origin`` (reference timeline; the
    camera's moved by ``prior``) whose data both streams have passed, a window in which either has no
    event stepped over (a gap, a clock jump), each with its index; and the next k to try."""
    T = p.window_ns
    out: list[tuple[int, Window]] = []
    while True:
        w = origin + k * T
        if ref.last_ns is None or cam.last_ns is None or min(ref.last_ns, cam.last_ns + prior) < w + T - 1:
            return out, k  # not whole yet
        nr, nc = ref.next_event_ns(w), cam.next_event_ns(w - prior)
        if nr is None or nc is None:
            return out, k
        later = max((nr - origin) // T, (nc + prior - origin) // T)
        if later > k:
            k = later
            continue
        out.append((k, paper_job(ref, cam, w, T, prior)))
        k += 1


def paper_job(ref: BinnedStream, cam: BinnedStream, w: int, length: int, prior: int) -> Window:
    """One window of the paper's: the reference's counts over [w, w + length), the camera's over that
    span moved by ``prior``."""
    return ref.snapshot(w, w + length), cam.snapshot(w - prior, w - prior + length), w, length, prior
