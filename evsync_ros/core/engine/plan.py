"""Where a camera's windows go: one plan for the rig, offline and live. numpy only.

Windows tile the reference's events from its first one (after its last silence or restart), on one
grid whatever the camera's prior (windows that shifted with it would share data, and agree by it).
Their length comes from the span both streams have had since they (re)started, on the reference's
own clock (``schedule.window_length_ns``, its 1-2-5 ladder): it grows with the recording, and starts
short again after a jump. A window is fitted once the camera's data reach past it by the search's
reach; at the end of a recording (``ended``) once they reach it.
"""

from __future__ import annotations

from collections.abc import Container

from evsync_ros.core.bins import BinnedStream, GridCounts
from evsync_ros.core.engine.params import OnlineParams
from evsync_ros.core.results import Method
from evsync_ros.core.schedule import plan

__all__ = ['job', 'window_jobs']

Job = tuple[GridCounts, GridCounts, int, int, int]
"""(reference counts, camera counts, window start, length, prior): what ``windows.fit_one`` takes."""


def window_jobs(p: OnlineParams, ref: BinnedStream, cam: BinnedStream, *, ref_since: int | None,
                cam_since: int | None, prior: int, restart: int | None, resumed: bool,
                fitted: Container[tuple[int, int]], last_start: int | None, ended: bool, whole: bool) -> list[Job]:
    """The camera's windows whose data are complete and that have not been fitted (module notes).
    ``whole``: every window since the start (offline), else those of the drift span (live);
    ``resumed``: the camera's events since ``cam_since`` follow a silence or a restart."""
    ref_last, cam_last, origin = ref.last_ns, cam.last_ns, ref.origin_ns
    if ref_last is None or cam_last is None or origin is None or ref_since is None or cam_since is None:
        return []
    g = p.grid_ns
    if p.method is Method.PAPER:
        return _paper(p, ref, cam, since=max(ref_since, cam_since + prior), origin=origin, prior=prior,
                      last_start=last_start)
    since = ref_since + -(ref_since - origin) % g
    reach = p.reach_ns
    length = p.refined.window_length(ref_last - max(since, cam_since + prior), tile=False)
    if length % g:
        return []
    newest = min(ref_last, cam_last + prior - (0 if ended else reach))
    # a window may begin before the camera's very first event by what it can spare and still pair
    # ``min_overlap`` of its bins (a camera a few ms later than the reference keeps its first window),
    # never before its return from a silence or a restart (no window spans the stream's gap)
    spare = 0 if resumed else int(length * (1 - p.refined.min_overlap))
    floor = max(since, cam_since + prior - spare, restart if restart is not None else since)
    if not whole:
        floor = max(floor, newest - p.drift_span_ns - length)
    first = since + -(-(floor - since) // length) * length  # on the windows' grid
    return [job(p, ref, cam, w, length, prior) for w in _starts(ref, first, newest, length)
            if (w, length) not in fitted]


def job(p: OnlineParams, ref: BinnedStream, cam: BinnedStream, w: int, length: int, prior: int) -> Job:
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


def _paper(p: OnlineParams, ref: BinnedStream, cam: BinnedStream, *, since: int, origin: int, prior: int,
           last_start: int | None) -> list[Job]:
    """The paper's method live: the newest whole window of T, at least ``hop_ns`` after the last."""
    T, g = p.window_ns, p.grid_ns
    since += -(since - origin) % g
    assert ref.last_ns is not None and cam.last_ns is not None
    w = min(ref.last_ns, cam.last_ns + prior) - T
    w -= (w - since) % g
    if w < since or (last_start is not None and w < last_start + p.hop_ns):
        return []
    return [(ref.snapshot(w, w + T), cam.snapshot(w - prior, w - prior + T), w, T, prior)]
