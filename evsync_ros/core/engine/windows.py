"""One window fitted by either method, and what a camera's windows say: the two calls the engine
hands its runner (a process of its own, live). numpy only."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from evsync_ros.core.agreement import STRETCH_ADVICE
from evsync_ros.core.bins import GridCounts
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine.params import OnlineParams
from evsync_ros.core.paper import WindowResult, estimate_window_counts
from evsync_ros.core.refined import RefinedParams, camera_result, fit_window, with_smoothing
from evsync_ros.core.results import CameraFit, Method, WindowFit

__all__ = ['Known', 'centre_of', 'clearer', 'departing', 'fit_one', 'newest_line', 'on_stretch',
           'stretch_of', 'with_whole']


def fit_one(params: OnlineParams, ref_counts: GridCounts, cam_counts: GridCounts, w: int, length: int, prior: int,
            index: int, whole: bool = False) -> WindowFit | WindowResult:
    """One window of a camera fitted by the engine's method (``index``: the paper's window number;
    ``whole``: the refined fit with its curve and counts, else without: ``WindowFit.light``)."""
    if params.method is Method.REFINED:
        fit = fit_window(ref_counts, cam_counts, ref_start_ns=w, length_ns=length, prior_ns=prior,
                         params=params.refined)
        return fit if whole else fit.light()
    n, tau = params.paper.n_bins, params.paper.tau_ns
    return estimate_window_counts(ref_counts.counts(w, tau, n), cam_counts.counts(w - prior, tau, n),
                                  ref_start_ns=w, cam_start_ns=w - prior, index=index, params=params.paper)


@dataclass(frozen=True)
class Known:
    """What a camera's decision knows beyond its windows."""

    systematic_ns: float = 0.0
    """Its own systematic error (cameras of another model than the reference's)."""
    skew_ppm: float = 0.0
    """The skew its times were binned through, about ``anchor_ns`` (an offline second pass)."""
    anchor_ns: int = 0
    skew_se_ppm: float = math.inf


def newest_line(topic: str, fits: list[WindowFit], newest: list[WindowFit] | None, params: RefinedParams,
                known: Known = Known()) -> tuple[CameraFit, CameraFit | None]:
    """A camera's decision from its windows (``refined.camera_result``), and from its newest ones
    alone where they are given."""
    return (camera_result(topic, fits, params, systematic_ns=known.systematic_ns, skew_ppm=known.skew_ppm,
                          anchor_ns=known.anchor_ns, skew_se_ppm=known.skew_se_ppm),
            None if newest is None else camera_result(topic, newest, params, systematic_ns=known.systematic_ns))


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


def departing(c: ClockCorrection, fits: list[WindowFit], p: OnlineParams) -> list[WindowFit] | None:
    """The newest ``min_agreeing`` windows when every one of them has a clear peak away from
    correction ``c`` (more than ``step_ns`` and 5 of its standard errors): a clock step, if they
    agree on a line of their own. None otherwise."""
    newest = [f for f in fits[-p.refined.min_agreeing:] if f.has_data and math.isfinite(f.se_ns)]
    if len(newest) < p.refined.min_agreeing:
        return None
    departs = [abs(f.offset_ns - (c.apply_one(centre_of(f)) - centre_of(f))) > max(p.step_ns, 5 * f.se_ns)
               for f in newest]
    return newest if all(departs) else None


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
