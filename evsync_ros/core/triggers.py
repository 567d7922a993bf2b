"""Trigger edges against a density estimate: one pulse's edges matched across a camera and the
reference, the offset they give, and the estimate's error against it (docs/triggers.md)."""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.results import CameraFit

__all__ = ['AMBIGUITY_MARGIN_NS', 'EDGE_PAIRS', 'SIGMAS', 'WITHIN_SE', 'EdgeBuffer', 'Edges', 'Verdict', 'Verified',
           'ambiguous', 'by_edges', 'edge_anchor', 'edge_line', 'match', 'period_ns', 'tie', 'verify']

SIGMAS = 5
"""The density offset's bound, in its standard errors, that must pick one pulse of a periodic train."""
AMBIGUITY_MARGIN_NS = 10_000_000
"""Added to twice that bound: a period shorter than the sum is ambiguous (the makes' lag, unmodelled)."""
WITHIN_SE = 3
"""An estimate lies within its stated error when its error against the edges is at most this many
standard errors."""
EDGE_PAIRS = 4
"""The fewest edges matched for a camera's line to be taken from its edges (``by_edges``)."""
EDGES_KEPT = 4096
"""Edges a live stream keeps (``EdgeBuffer``): at 10 Hz, nearly seven minutes."""


@dataclass(frozen=True)
class Edges:
    """One camera's edges on the channel that carries the shared pulse: times (int64 ns, its own
    timeline) and values (1 rising, 0 falling)."""

    t: npt.NDArray[np.int64]
    value: npt.NDArray[np.uint8]


class EdgeBuffer:
    """A live stream's newest edges (at most ``EDGES_KEPT``), on its own timeline."""

    def __init__(self) -> None:
        self.t = np.empty(0, np.int64)
        self.value = np.empty(0, np.uint8)

    def add(self, t: npt.NDArray[np.int64], value: npt.NDArray[np.uint8]) -> None:
        self.t = np.concatenate([self.t, np.asarray(t, np.int64)])[-EDGES_KEPT:]
        self.value = np.concatenate([self.value, np.asarray(value, np.uint8)])[-EDGES_KEPT:]

    @property
    def edges(self) -> Edges:
        return Edges(self.t, self.value)


class Verdict(enum.Enum):
    """What the edges could say of a camera's estimate."""

    VERIFIED = 'verified'
    REFERENCE = 'reference'
    NO_EDGES = 'no edges'
    NOT_ACCEPTED = 'not accepted'
    AMBIGUOUS = 'ambiguous'
    UNMATCHED = 'unmatched'


@dataclass(frozen=True)
class Verified:
    """A camera's density estimate against its trigger edges (``verify``)."""

    topic: str
    verdict: Verdict
    reason: str = ''
    edges: int = 0
    matched: int = 0
    period_ns: int | None = None
    trigger: ClockCorrection | None = None
    """What the edges give: the camera onto the reference, about the estimate's anchor."""
    error_ns: float | None = None
    """The estimate's offset minus the edges' at its anchor (signed: what a calibration stores)."""
    stated_ns: float | None = None
    """The estimate's own standard error."""
    window_errors_ns: tuple[float, ...] = ()
    """Each agreeing window's offset minus the edges' at the window's middle."""

    @property
    def within(self) -> bool | None:
        """Whether the error lies within ``WITHIN_SE`` stated standard errors (None: not measured)."""
        if self.error_ns is None or self.stated_ns is None or not math.isfinite(self.stated_ns):
            return None
        return abs(self.error_ns) <= WITHIN_SE * self.stated_ns

    def window_stats(self) -> dict[str, float] | None:
        """Signed mean, mean and max of the magnitude, standard deviation of the windows' errors."""
        e = np.asarray(self.window_errors_ns, dtype=np.float64)
        if e.size == 0:
            return None
        return {'mean_ns': float(e.mean()), 'mean_abs_ns': float(np.abs(e).mean()),
                'max_abs_ns': float(np.abs(e).max()), 'std_ns': float(e.std(ddof=1)) if e.size > 1 else 0.0}

    def as_json(self) -> dict[str, object]:
        t = self.trigger
        return {'topic': self.topic, 'verdict': self.verdict.value, 'reason': self.reason, 'edges': self.edges,
                'matched': self.matched, 'period_ns': self.period_ns,
                'trigger_offset_ns': None if t is None else t.offset_ns,
                'trigger_skew_ppm': None if t is None else t.skew_ppm, 'anchor_ns': None if t is None else t.anchor_ns,
                'error_ns': self.error_ns, 'uncertainty_ns': self.stated_ns, 'within': self.within,
                'windows': self.window_stats()}


def period_ns(edges: Edges) -> int | None:
    """The pulse's period: the median time between rising edges (None: fewer than two)."""
    rising = edges.t[edges.value == 1]
    return int(np.median(np.diff(rising))) if rising.size > 1 else None


def ambiguous(period: int | None, se_ns: float) -> bool:
    """Whether a density offset known to ``se_ns`` cannot pick one pulse of a train of ``period``."""
    return period is not None and period < 2 * SIGMAS * se_ns + AMBIGUITY_MARGIN_NS


def match(ref: Edges, cam: Edges, correction: ClockCorrection, *, within_ns: float
          ) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """(camera index, reference index) of each camera edge whose nearest reference edge of the same
    value, with the camera's times through ``correction``, is within ``within_ns``; a reference edge
    claimed twice keeps neither."""
    mapped = correction.apply(cam.t)
    cams, refs = [], []
    for value in (0, 1):
        ci = np.flatnonzero(cam.value == value)
        ri = np.flatnonzero(ref.value == value)
        if ci.size == 0 or ri.size == 0:
            continue
        rt = ref.t[ri]
        pos = np.clip(np.searchsorted(rt, mapped[ci]), 1, rt.size - 1) if rt.size > 1 else np.zeros(ci.size, int)
        left = np.maximum(pos - 1, 0)
        nearest = np.where(np.abs(rt[left] - mapped[ci]) <= np.abs(rt[pos] - mapped[ci]), left, pos)
        ok = np.abs(rt[nearest] - mapped[ci]) <= within_ns
        cams.append(ci[ok])
        refs.append(ri[nearest[ok]])
    c = np.concatenate(cams) if cams else np.empty(0, np.intp)
    r = np.concatenate(refs) if refs else np.empty(0, np.intp)
    claimed, times = np.unique(r, return_counts=True)
    once = np.isin(r, claimed[times == 1])
    return c[once], r[once]


def edge_line(ref_t: npt.NDArray[np.int64], cam_t: npt.NDArray[np.int64], *, anchor_ns: int) -> ClockCorrection:
    """The correction that takes matched camera edge times onto the reference's: a line of their
    differences over the camera's time about ``anchor_ns`` (an offset alone from fewer than three,
    or edges within one second)."""
    d = (ref_t - cam_t).astype(np.float64)
    x = (cam_t - anchor_ns).astype(np.float64)
    if d.size < 3 or np.ptp(x) < 1e9:
        return ClockCorrection(offset_ns=round(float(np.median(d))), anchor_ns=anchor_ns)
    slope, intercept = np.polyfit(x, d, 1)
    return ClockCorrection(offset_ns=round(float(intercept)), skew_ppm=float(slope) * 1e6, anchor_ns=anchor_ns)


def verify(camera: CameraFit, ref: Edges | None, cam: Edges | None, *, reference: str) -> Verified:
    """``camera``'s density estimate against the edges: the verdict, and where verified its error."""
    if camera.topic == reference:
        return Verified(camera.topic, Verdict.REFERENCE, 'the ruler', edges=0 if cam is None else cam.t.size)
    edges = 0 if cam is None else int(cam.t.size)
    if cam is None or cam.t.size == 0 or ref is None or ref.t.size == 0:
        whose = 'the reference has' if cam is not None and cam.t.size else 'it has'
        return Verified(camera.topic, Verdict.NO_EDGES, f'{whose} no trigger edges', edges=edges)
    se = camera.uncertainty_ns
    if not camera.accepted or se is None or not math.isfinite(se):
        return Verified(camera.topic, Verdict.NOT_ACCEPTED, 'no accepted density estimate picks the pulse',
                        edges=edges)
    period = period_ns(ref)
    if period is not None and ambiguous(period, se):
        return Verified(camera.topic, Verdict.AMBIGUOUS, f'ambiguous: period {period / 1e6:g} ms', edges=edges,
                        period_ns=period)
    within = (period / 2 if period is not None else SIGMAS * se + AMBIGUITY_MARGIN_NS)
    ci, ri = match(ref, cam, camera.correction, within_ns=within)
    if ci.size == 0:
        return Verified(camera.topic, Verdict.UNMATCHED, 'no edge of it near one of the reference\'s', edges=edges,
                        period_ns=period)
    line = edge_line(ref.t[ri], cam.t[ci], anchor_ns=camera.anchor_ns)
    return Verified(camera.topic, Verdict.VERIFIED, edges=edges, matched=int(ci.size), period_ns=period,
                    trigger=line, error_ns=float(camera.offset_ns - line.offset_ns), stated_ns=float(se),
                    window_errors_ns=_window_errors(camera, line))


def _window_errors(camera: CameraFit, line: ClockCorrection) -> tuple[float, ...]:
    """Each agreeing window's offset minus the edges' line at the window's middle (camera time)."""
    out = []
    for w in camera.windows:
        if not w.accepted:
            continue
        middle = w.ref_start_ns + w.length_ns // 2 - w.offset_ns
        out.append(float(w.offset_ns - (line.apply_one(middle) - middle)))
    return tuple(out)


def by_edges(fit: CameraFit, ref: Edges, cam: Edges) -> CameraFit:
    """A camera's accepted density decision with its line taken from the trigger edges, where they
    can: the decision picks the pulse, the edges give the offset and skew to microseconds (``verify``,
    with at least ``EDGE_PAIRS`` matched); its ``edges`` and ``density_offset_ns`` say so. Else
    ``fit`` as it is: the edges are the strongest evidence, but only of a pulse the density picked."""
    if not fit.accepted or ref.t.size == 0 or cam.t.size == 0:
        return fit
    v = verify(fit, ref, cam, reference='')
    if v.verdict is not Verdict.VERIFIED or v.trigger is None or v.matched < EDGE_PAIRS:
        return fit
    line = v.trigger
    ci, ri = match(ref, cam, line, within_ns=(v.period_ns or 0) / 2 or SIGMAS * (v.stated_ns or 0.0))
    resid = (ref.t[ri] - line.apply(cam.t[ci])).astype(np.float64)
    se = max(float(resid.std(ddof=1)) / math.sqrt(resid.size) if resid.size > 1 else 1_000.0, 100.0)
    return replace(fit, offset_ns=line.offset_ns, skew_ppm=line.skew_ppm, anchor_ns=line.anchor_ns,
                   uncertainty_ns=se, edges=int(ci.size), density_offset_ns=fit.offset_ns)


def edge_anchor(fits: Mapping[str, CameraFit], edges: Mapping[str, Edges], *, reference: str,
                keep: str | None = None) -> str | None:
    """The camera the others' edges are tied to: the reference where it has edges; else ``keep``
    while it can be one (a live anchor stays, so that its cameras' lines do not swap at every
    decision), or of the cameras with edges the one whose accepted density decision is known best
    (None: no such)."""
    if reference in edges and edges[reference].t.size:
        return reference
    held = [t for t, e in edges.items() if e.t.size and t in fits and fits[t].accepted
            and fits[t].uncertainty_ns is not None and math.isfinite(fits[t].uncertainty_ns or math.inf)]
    if keep in held:
        return keep
    return min(held, key=lambda t: (fits[t].uncertainty_ns, t)) if held else None


def tie(fit: CameraFit, fits: Mapping[str, CameraFit], edges: Mapping[str, Edges], *, reference: str,
        anchor: str | None) -> CameraFit:
    """One camera's decision with its line tied edge to edge (``by_edges``) to ``anchor``'s edges
    (``edge_anchor``). ``fits`` are the density decisions, ``edges`` each camera's on the shared
    pulse. Tied to another camera than the reference, the line is the anchor's density line and the
    edges between the two, known as well as both together (the anchor's standard error and the
    edges', in quadrature); ``tied_to`` names that camera. Else ``fit`` as it is."""
    own = edges.get(fit.topic)
    if anchor is None or anchor == fit.topic or own is None or not own.t.size:
        return fit
    if anchor == reference:
        return by_edges(fit, edges[reference], own)
    a = fits[anchor]
    placed = Edges(a.correction.apply(edges[anchor].t), edges[anchor].value)
    out = by_edges(fit, placed, own)
    if not out.edges:
        return out
    return replace(out, uncertainty_ns=math.hypot(out.uncertainty_ns or 0.0, a.uncertainty_ns or 0.0), tied_to=anchor)
