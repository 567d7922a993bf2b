"""A camera's decision from its windows: pure functions of the windows fitted, what is known beyond
them and the parameters, the same for every driver (docs/method.md, "One engine"). numpy only."""

from __future__ import annotations

import math
from dataclasses import replace

from evsync_ros.core.agreement import STRETCH_ADVICE
from evsync_ros.core.engine.stream import Known
from evsync_ros.core.refined import RefinedParams, camera_result, with_smoothing
from evsync_ros.core.results import CameraFit, WindowFit

__all__ = ['centre_of', 'clearer', 'decide', 'on_stretch', 'since_step', 'stepped_from', 'stretch_of', 'with_whole']


def decide(topic: str, fits: list[WindowFit], params: RefinedParams, known: Known = Known()) -> CameraFit:
    """A camera's decision from its windows (``refined.camera_result``), with what it knows beyond them."""
    return camera_result(topic, fits, params, systematic_ns=known.systematic_ns, skew_ppm=known.skew_ppm,
                         anchor_ns=known.anchor_ns, skew_se_ppm=known.skew_se_ppm)


def stepped_from(fit: CameraFit) -> int | None:
    """Where a decision refused for a clock step begins its newest stretch (reference timeline): the
    run off the line where it reaches the newest window, else the window after it (the clock came back
    or the run is the older part). None when the decision saw no step. The one clock-step rule: the
    offline driver refuses such a camera, the live one restarts its line there."""
    if fit.step is None:
        return None
    first, last = fit.step
    at = first if last == len(fit.windows) - 1 else last + 1
    return fit.windows[at].ref_start_ns


def since_step(fits: dict[tuple[int, int], WindowFit], *, restart_ns: int | None, back_ns: int | None
               ) -> dict[tuple[int, int], WindowFit]:
    """The windows of ``fits`` (by (start, length)) a decision is found from, live as offline: those
    since the camera's last clock step (``restart_ns``) and its return from a silence (``back_ns``:
    its windows start short again), of the longest length (the grid only grows), in order."""
    floor = max(restart_ns if restart_ns is not None else -(1 << 62), back_ns if back_ns is not None else -(1 << 62))
    since = [k for k in fits if k[0] >= floor]
    length = max((k[1] for k in since), default=0)
    return dict(sorted((k, fits[k]) for k in since if k[1] == length))


def clearer(fit: WindowFit, than: WindowFit | None) -> bool:
    """Whether ``fit`` is a window a report should rather draw whole than ``than``: a longer one (the
    plan's windows only grow, and a decision reads the longest), else a more confident one."""
    if than is None:
        return True
    peak = -math.inf if math.isnan(fit.peak) else fit.peak
    other = -math.inf if math.isnan(than.peak) else than.peak
    return (fit.length_ns, fit.confidence, peak) > (than.length_ns, than.confidence, other)


def with_whole(windows: tuple[WindowFit, ...], whole: WindowFit | None) -> tuple[WindowFit, ...]:
    """A decision's windows with ``whole`` (the camera's most confident, with its curve and counts) in
    place of its light copy, under the smoothing and mark the decision gave that window."""
    if whole is None:
        return windows
    key = (whole.ref_start_ns, whole.length_ns)
    return tuple(replace(with_smoothing(whole, w.smooth_ns), accepted=w.accepted)
                 if (w.ref_start_ns, w.length_ns) == key else w for w in windows)


def centre_of(fit: WindowFit) -> int:
    """A window's centre on the camera's timeline."""
    return fit.ref_start_ns + fit.length_ns // 2 - fit.offset_ns


def stretch_of(est: CameraFit) -> tuple[int, int] | None:
    """The stretch [start, end) of the reference's timeline where a decision's agreeing windows lie,
    when the others are quiet (``CameraFit.stretch_ns``); None otherwise."""
    return est.stretch_ns if est.windows and not est.accepted else None


def on_stretch(est: CameraFit, alone: CameraFit) -> CameraFit:
    """A decision refused only for quiet windows outside its stretch, and ``alone``, that stretch
    decided on its own shorter windows: accepted when the stretch is, and its line holds each of the
    longer windows that agreed (the stretch consistent with itself at both lengths); else refused,
    the reason saying why the stretch was not enough."""
    if alone.accepted and alone.uncertainty_ns is not None:
        off = [f for f in est.windows if f.accepted and abs(
            f.offset_ns - (alone.correction.apply_one(centre_of(f)) - centre_of(f)))
            > 3 * math.hypot(f.se_ns, alone.uncertainty_ns)]
        if not off:
            return alone
        why = f'{len(off)} of its longer windows off its own line'
    else:
        why = alone.reason
    return replace(est, reason=f'{est.reason.replace(STRETCH_ADVICE, "")}; that stretch alone: {why}')
