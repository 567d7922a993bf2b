"""Acceptance by agreement: a camera's offset is accepted only when independent windows agree on it.

numpy only. Each window of a camera gives an offset with a standard error (``refined.fit_window``:
a jackknife over the window's own blocks) and its best few coarse candidates. The windows whose
peak is clear (a finite standard error) are the evidence, each error taken as at least half the
median of them (``POOLED_SE``). Among them the largest set that fits one line,
offset(t) = offset + skew * (t - anchor), each within 3 of its own standard errors, is found
robustly: lines through pairs of windows (and constant lines through single ones) are tried and
the one most windows agree with wins, so a wrong window is outvoted, never averaged in. The line
is then fitted to the agreeing windows by weighted least squares, its errors scaled up when the
windows scatter more than their standard errors say (Birge ratio, over the agreeing windows and
those left out that still lie on the line's own peak), and what averaging cannot take away added in
quadrature: a systematic floor, and the agreeing windows' own spread about the line (``spread``).
A skew is kept only when significant (``SKEW_SIGNIFICANCE``), unless it is known to exist
(``skew_known``: a second pass, whose windows had the first pass's skew taken out).

The offset is accepted when all of these hold, and otherwise the first that fails is the reason:

* enough windows: at least ``min_agreeing`` windows with data of both cameras, and as many with a
  clear peak;
* agreement: at least ``min_agreeing`` windows agree, and they are at least ``min_confidence`` of
  the windows with a clear peak;
* not by chance: so many windows could agree by accident only with a probability under ``chance``
  (the most precise agreeing window places the line, each other lands within its tolerance of it
  with the probability of that tolerance over the search range; every way to pick them is counted);
* no clock step: no run of consecutive windows off the line agrees on an offset of its own, as
  closely as chance allows only under ``chance`` (``_step``: the camera's clock jumped, and no one
  line holds the recording);
* not ambiguous: no other offset (farther than the main lobe) is among the best candidates of
  nearly as many windows, nearly as high (periodic motion);
* precise enough: the offset's standard error is at most ``max_uncertainty_ns``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from evsync_ros.core.results import Reason

SIGMAS = 3.0
"""A window agrees with a line when within this many standard errors (its own and the line's)."""
AMBIGUOUS_SHARE = 0.6
"""An alternative offset that this share of the agreeing windows also support makes it ambiguous ..."""
AMBIGUOUS_HEIGHT = 0.95
"""... counting a window's alternative only when its correlation is this close to the window's best."""
MAX_PAIRS = 4000
"""Lines tried through pairs of windows at most (a seeded sample beyond; neighbours always)."""
POOLED_SE = 0.5
"""A window's standard error is taken as at least this share of the median over the camera's windows
with a clear peak (a jackknife estimate of 9 degrees of freedom falls under half the true error
about once in a hundred windows; a window that precise would otherwise decide the line alone)."""
QUIET_OUTSIDE = Reason.QUIET_OUTSIDE.value
"""How a reason begins when the windows off the line are quiet, not disagreeing (``_quiet_elsewhere``);
its kind says so; the engine then decides the stretch alone (``engine.decide.stretch_of``)."""
STRETCH_ADVICE = ' (estimate that stretch alone, --start and --duration, for shorter windows)'
"""What a reason of quiet windows outside a stretch advises (``engine.windows.on_stretch`` drops it
where the engine tried that stretch itself)."""
QUIET_MARGIN = 0.1
"""A window whose best coarse peak stands out of its best rival by less than this share of what the
rival leaves below 1 ((best - rival) / (1 - rival)) shows no motion both cameras share (``stands_out``)."""
FAINT_SHARE = 0.5
"""A window whose best coarse peak is under this share of the camera's highest is faint: the motion
both cameras share is elsewhere, and a faint window that lands on a line by chance is no evidence for
it (``_loud``)."""
SKEW_SIGNIFICANCE = 3.0
"""A fitted skew is kept when it is as significant as this many standard errors of a normal variable
(else the offset is constant). When the windows scatter about the line more than their own errors
say (Birge ratio over 1), the line's errors are that scatter, estimated from the few windows that
agree, and the threshold is Student's t with as many degrees of freedom (``t_critical``): 9.2
standard errors for 5 windows, 4.3 for 10, 3.3 for 32. (Jittered EVK4 splits fitted skews of 86-137
ppm where there was none, at 3.2 of such errors, from 5 windows.)"""


@dataclass(frozen=True, kw_only=True)
class Evidence:
    """What the agreement reads of one window (``refined.WindowFit`` has all of it)."""

    centre_ns: int
    """Window centre on the camera's timeline."""
    offset_ns: int
    se_ns: float
    """Standard error of the offset; inf when the window has no clear peak."""
    candidates: tuple[tuple[int, float], ...] = ()
    """(offset, correlation) of the window's best coarse peaks, best first."""
    has_data: bool = True


@dataclass(frozen=True, kw_only=True)
class Agreement:
    """The outcome for one camera."""

    accepted: bool
    reason: str
    """Why not accepted ('' when accepted)."""
    kind: Reason
    """The kind of ``reason``."""
    offset_ns: int
    """The line's offset at ``anchor_ns`` (the best single window's when no line was found)."""
    skew_ppm: float
    anchor_ns: int
    se_ns: float
    """Standard error of the offset at the anchor, systematic floor included (inf: none)."""
    skew_se_ppm: float
    agreeing: tuple[bool, ...]
    """Per window: whether it agrees with the line."""
    informative: int
    """Windows with a clear peak."""
    with_data: int
    chance: float
    """How likely so many windows would agree by accident."""
    step: tuple[int, int] | None = None
    """The first and last of a run of consecutive windows (indices of ``windows``) that agrees on an
    offset of its own, off the line (``_step``): the camera's clock jumped, and no one line holds."""
    spread_ns: float = 0.0
    """The agreeing windows' weighted spread about the line (``spread``), part of ``se_ns``."""

    @property
    def stepped(self) -> bool:
        """The camera's clock stepped (``step``)."""
        return self.step is not None

    @property
    def quiet_outside(self) -> bool:
        """Refused only for quiet windows outside the stretch the agreeing windows span (``_quiet_elsewhere``)."""
        return self.kind is Reason.QUIET_OUTSIDE


def _weighted_line(x: npt.NDArray[np.float64], y: npt.NDArray[np.float64], var: npt.NDArray[np.float64], *,
                   slope: bool) -> tuple[float, float, float, float, float, float]:
    """(offset at the weighted centre, slope, centre, se offset, se slope, Birge ratio) by WLS."""
    w = 1.0 / var
    xc = float(np.sum(w * x) / np.sum(w))
    dx = x - xc
    sw = float(np.sum(w))
    sxx = float(np.sum(w * dx * dx))
    if slope and x.size >= 3 and sxx > 0:
        b = float(np.sum(w * dx * y) / sxx)
        dof = x.size - 2
    else:
        b = 0.0
        dof = x.size - 1
    a = float(np.sum(w * (y - b * dx)) / sw)
    resid = y - a - b * dx
    chi2 = float(np.sum(w * resid * resid))
    birge = math.sqrt(chi2 / dof) if dof > 0 else 1.0
    scale = max(1.0, birge)
    se_a = scale / math.sqrt(sw)
    se_b = scale / math.sqrt(sxx) if b != 0.0 or (slope and sxx > 0 and x.size >= 3) else math.inf
    return a, b, xc, se_a, se_b, birge


def agree(windows: Sequence[Evidence], *, search_ns: int, lobe_ns: int, min_agreeing: int = 3,
          min_share: float = 0.5, chance_limit: float = 1e-3, max_uncertainty_ns: float = 1e6,
          max_skew_ppm: float = 200.0, drift: bool = True, floor_ns: float = 10e3,
          systematic_ns: float = 5e3, near_ns: float = 2e6, skew_known: bool = False) -> Agreement:
    """The agreement of a camera's ``windows`` (their evidence, in time order; module notes).
    ``search_ns``: the width of the range each window searched (the chance a random peak lands anywhere
    in it); ``lobe_ns``: offsets closer than this to the line are the same peak (ambiguity is sought
    beyond); ``min_agreeing``, ``min_share``, ``chance_limit``, ``max_uncertainty_ns``: the acceptance
    conditions; ``max_skew_ppm``: no line steeper is tried; ``drift``: fit a skew; ``floor_ns``, and
    ``systematic_ns``: added in quadrature to each window's error, and to the camera's (not averaged
    down); ``near_ns``: a window off the line this close to it measured the same peak (its scatter
    counts in the line's errors); ``skew_known``: a second pass's windows, whose residual skew is kept
    even when not significant (still within ``max_skew_ppm``)."""
    k = len(windows)
    with_data = sum(w.has_data for w in windows)
    inf_idx = np.array([i for i, w in enumerate(windows) if w.has_data and math.isfinite(w.se_ns)], dtype=np.int64)
    n_inf = int(inf_idx.size)
    short = _too_little(windows, with_data=with_data, informative=n_inf, min_agreeing=min_agreeing)
    if short is not None:
        return short
    x0, y0, xs, y, se, var = _coordinates([windows[i] for i in inf_idx], floor_ns=floor_ns)
    sd = np.sqrt(var)
    inl = _inliers(xs, y, var, sd, drift=drift, max_skew_ppm=max_skew_ppm)
    n_in = int(inl.sum())
    a, b, xc, se_a, se_b, flat_se, near = _fitted(xs, y, var, inl, drift=drift, skew_known=skew_known,
                                                  max_skew_ppm=max_skew_ppm, near_ns=near_ns)
    anchor = x0 + int(round(xc))
    skew = b * 1e6
    spread_ns = spread(y[inl] - a - b * (xs[inl] - xc), var[inl])
    se_total = math.sqrt(se_a * se_a + systematic_ns * systematic_ns + spread_ns * spread_ns)
    agreeing = [False] * k
    for pos, i in enumerate(inf_idx.tolist()):
        agreeing[i] = bool(inl[pos])
    chance = _chance(xs[inl], se[inl], n_inf, search_ns, max_skew_ppm if drift else 0.0)

    def verdict(kind: Reason = Reason.NONE, reason: str = '', *, step: tuple[int, int] | None = None) -> Agreement:
        return Agreement(accepted=kind is Reason.NONE, reason=reason, kind=kind, offset_ns=y0 + int(round(a)),
                         skew_ppm=skew if b != 0.0 else 0.0, anchor_ns=anchor, se_ns=se_total,
                         skew_se_ppm=se_b * 1e6 if b != 0.0 else flat_se * 1e6, agreeing=tuple(agreeing),
                         informative=n_inf, with_data=with_data, chance=chance, step=step, spread_ns=spread_ns)

    def quiet_elsewhere() -> str:  # the reason when only quiet windows keep the line from being accepted
        clear = [windows[i] for i in inf_idx]
        loud = inl & _loud(clear)
        quiet = _quiet_elsewhere(windows, clear, loud, min_agreeing, min_share, n_inf) if (
            loud.sum() < min_agreeing or loud.sum() < min_share * n_inf) else ''
        if quiet:  # faint windows that joined the line are no evidence either way: the stretch decides
            for pos, i in enumerate(inf_idx.tolist()):
                agreeing[i] = bool(loud[pos])
        return quiet

    def refused(kind: Reason, reason: str) -> Agreement:  # unless only quiet windows keep it from the line
        quiet = quiet_elsewhere()
        return verdict(Reason.QUIET_OUTSIDE, quiet) if quiet else verdict(kind, reason)

    if n_in < min_agreeing or n_in < min_share * n_inf:
        return refused(
            Reason.DISAGREE,
            f'windows disagree: at most {n_in} of the {n_inf} windows with a clear peak agree on one offset '
            f'(needs {max(min_agreeing, math.ceil(min_share * n_inf))}); different scenes or too little shared motion')
    if chance > chance_limit:
        return refused(
            Reason.CHANCE,
            f'could be chance: {n_in} windows agree within {float(np.median(se[inl])) / 1e6:.2f} ms, which happens '
            f'by accident with probability {chance:.1g} over a {search_ns / 1e9:g} s search')
    step = _step(xs, y, sd, inl | near, [windows[i] for i in inf_idx], y0, a, b, xc, search_ns, lobe_ns,
                 chance_limit)
    if step is not None:
        first, last, shift = step
        return verdict(
            Reason.CLOCK_STEP,
            f'clock step: the {last - first + 1} windows with a clear peak centred {(xs[first] - xs[0]) / 1e9:.1f}-'
            f'{(xs[last] - xs[0]) / 1e9:.1f} s after the first agree on an offset {shift / 1e6:+.3f} ms from the '
            f'line {n_in} others give, which no one line holds (the camera\'s clock jumped: estimate the stretches '
            f'apart)', step=(int(inf_idx[first]), int(inf_idx[last])))
    alt = _ambiguity([windows[i] for i in inf_idx[inl]], y0 + a, b, x0 + xc, lobe_ns)
    if alt is not None:
        shift, count = alt
        return verdict(
            Reason.AMBIGUOUS,
            f'ambiguous: {count} of the {n_in} agreeing windows fit an offset {shift / 1e6:+.1f} ms away nearly as '
            f'well (periodic motion?)')
    if se_total > max_uncertainty_ns:
        return refused(
            Reason.UNCERTAIN,
            f'uncertain: {n_in} windows agree, but the offset is known only to +-{se_total / 1e6:.2f} ms '
            f'(limit {max_uncertainty_ns / 1e6:g} ms)')
    return verdict()


def _too_little(windows: Sequence[Evidence], *, with_data: int, informative: int, min_agreeing: int
                ) -> Agreement | None:
    """The refusal of windows too few to agree (too short), or with too few clear peaks (too flat), at
    the best single window's offset; None when there are enough."""
    if with_data >= min_agreeing and informative >= min_agreeing:
        return None
    if with_data < min_agreeing:
        kind, reason = Reason.TOO_SHORT, (f'too short: {with_data} window(s) with events of both cameras, '
                                          f'agreement needs {min_agreeing}')
    else:
        kind, reason = Reason.TOO_FLAT, (f'too flat: {informative} of {with_data} windows have a clear peak, '
                                         f'agreement needs {min_agreeing} (too little shared motion, or different '
                                         'scenes)')
    best = min((w for w in windows if w.has_data), key=lambda w: w.se_ns, default=None)
    return Agreement(accepted=False, reason=reason, kind=kind, offset_ns=int(best.offset_ns if best else 0),
                     skew_ppm=0.0, anchor_ns=0, se_ns=math.inf, skew_se_ppm=math.inf,
                     agreeing=tuple(False for _ in windows), informative=informative, with_data=with_data,
                     chance=math.nan)


def _coordinates(clear: Sequence[Evidence], *, floor_ns: float) -> tuple[
        int, int, npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64],
        npt.NDArray[np.float64]]:
    """The windows with a clear peak as numbers to fit: (centre origin, offset origin, centres and
    offsets about them, errors, variances). Centres and offsets are taken as int64 about an integer
    origin each, then float64: times near 1e18 ns (a camera's clock decades from the reference's) would
    lose 256 ns steps as float64 themselves. A window's error is itself estimated (a jackknife of 10
    blocks: 9 degrees of freedom) and can come out far too small by chance; no window counts as more
    than 1 / POOLED_SE of the median."""
    centres = np.array([w.centre_ns for w in clear], dtype=np.int64)
    offsets = np.array([w.offset_ns for w in clear], dtype=np.int64)
    x0 = int(centres[0]) + int(round(float(np.mean(centres - centres[0]))))
    y0 = int(np.median(offsets))
    se = np.array([w.se_ns for w in clear], dtype=np.float64)
    se = np.maximum(se, POOLED_SE * float(np.median(se)))
    return (x0, y0, (centres - x0).astype(np.float64), (offsets - y0).astype(np.float64), se,
            se * se + floor_ns * floor_ns)


def _inliers(xs: npt.NDArray[np.float64], y: npt.NDArray[np.float64], var: npt.NDArray[np.float64],
             sd: npt.NDArray[np.float64], *, drift: bool, max_skew_ppm: float) -> npt.NDArray[np.bool_]:
    """The largest set of windows that fits one line, found robustly (module notes): the support of
    every candidate line (each window within SIGMAS of its own error and the line's at that window;
    a line through imprecise windows supports much loosely, so every distinct support set is refitted,
    weighted, and the set that keeps the most windows wins, then the most precise); the most precise
    window alone where none does."""
    lines = _candidate_lines(xs, y, max_skew_ppm if drift else 0.0)
    supports = np.empty((len(lines), y.size), dtype=bool)
    for row, ((a, b), (i, j)) in enumerate(lines):
        line_sd = _pair_line_sd(xs, sd, i, j, b != 0.0)
        supports[row] = np.abs(y - a - b * xs) <= SIGMAS * np.sqrt(sd * sd + line_sd * line_sd)
    best: tuple[int, float] | None = None
    inl = np.zeros(y.size, dtype=bool)
    first_of: dict[bytes, int] = {}  # each distinct support set once, in np.unique's (byte) order
    for row, packed in enumerate(np.packbits(supports, axis=1)):
        first_of.setdefault(packed.tobytes(), row)
    for row in [first_of[key] for key in sorted(first_of)]:
        start = supports[row]
        if start.sum() < 2:
            continue
        kept = _refit_inliers(xs, y, var, start, drift=drift)
        if kept.sum() < 1:
            continue
        _, _, _, se_kept, _, birge = _weighted_line(xs[kept], y[kept], var[kept], slope=drift)
        score = (int(kept.sum()), -se_kept * max(1.0, birge))
        if best is None or score > best:
            best, inl = score, kept
    if best is None:
        inl = np.zeros(y.size, dtype=bool)
        inl[int(np.argmin(sd))] = True
    return inl


def _fitted(xs: npt.NDArray[np.float64], y: npt.NDArray[np.float64], var: npt.NDArray[np.float64],
            inl: npt.NDArray[np.bool_], *, drift: bool, skew_known: bool, max_skew_ppm: float, near_ns: float
            ) -> tuple[float, float, float, float, float, float, npt.NDArray[np.bool_]]:
    """The line through the windows ``inl`` (offset at the weighted centre, slope, centre, their
    errors), constant where no skew is significant (what that leaves unknown of the skew: ``flat_se``,
    inf where no slope could be fitted), its errors grown by the windows near it (module notes); and
    those windows."""
    n_in = int(inl.sum())
    a, b, xc, se_a, se_b, birge = _weighted_line(xs[inl], y[inl], var[inl], slope=drift)
    significance = t_critical(n_in - 2) if birge > 1.0 else SKEW_SIGNIFICANCE
    flat_se = math.inf
    if drift and (b == 0.0 or (abs(b) < significance * se_b and not skew_known) or abs(b) * 1e6 > max_skew_ppm):
        # no skew the windows can tell, or one no clock has (windows a second or two apart, each off
        # by a fraction of a millisecond, can draw any slope): the offset is constant, and the skew
        # zero to within what the windows' slope leaves open (its value and error, no more than any
        # clock's skew): a constant line is never accepted as if known to be flat
        if math.isfinite(se_b):  # a slope was fitted: windows at three or more times
            flat_se = min(math.hypot(b, se_b), max_skew_ppm * 1e-6)
        a, b, xc, se_a, se_b, birge = _weighted_line(xs[inl], y[inl], var[inl], slope=False)
    # windows left out that still lie on the line's own peak (within near_ns) measured that peak, only
    # worse than their errors say: the windows' errors are too small, so the line's are scaled up by
    # how all of them scatter about it (a window on another peak is outvoted, not counted)
    near = ~inl & (np.abs(y - a - b * (xs - xc)) <= near_ns)
    if near.any():
        both = inl | near
        resid = y[both] - a - b * (xs[both] - xc)
        dof = int(both.sum()) - (2 if b != 0.0 else 1)
        scale = math.sqrt(float(np.sum(resid * resid / var[both])) / dof) if dof > 0 else 1.0
        grow = max(1.0, scale) / max(1.0, birge)
        if grow > 1.0:
            se_a, se_b = se_a * grow, se_b * grow
    return a, b, xc, se_a, se_b, flat_se, near


def stands_out(window: Evidence) -> float:
    """How far a window's best coarse peak stands out of its best rival: (best - rival) / (1 - rival),
    1 with no rival."""
    if len(window.candidates) < 2:
        return 1.0
    best, rival = window.candidates[0][1], window.candidates[1][1]
    return (best - rival) / (1.0 - rival) if rival < 1.0 else 0.0


def _loud(informative: Sequence[Evidence]) -> npt.NDArray[np.bool_]:
    """Per window: whether it shows motion both cameras share, its best coarse peak standing out of
    its rivals (``QUIET_MARGIN``) and at least ``FAINT_SHARE`` of the camera's highest (a window
    without candidates counts as loud: nothing says otherwise)."""
    top = max((w.candidates[0][1] for w in informative if w.candidates), default=0.0)
    return np.array([not w.candidates or (stands_out(w) >= QUIET_MARGIN and w.candidates[0][1] >= FAINT_SHARE * top)
                     for w in informative], dtype=bool)


def _quiet_elsewhere(windows: Sequence[Evidence], informative: Sequence[Evidence], inl: npt.NDArray[np.bool_],
                     min_agreeing: int, min_share: float, n_inf: int) -> str:
    """The reason when the windows off the line (``inl``) are quiet, not disagreeing: none of them is
    loud (``_loud``), while those on it all stand out of their rivals. Says where the motion was
    ('' when that is not so: the windows disagree)."""
    on = [w for w, k in zip(informative, inl) if k]
    off = [w for w, k, loud in zip(informative, inl, _loud(informative)) if not k and loud]
    if not on or len(on) == len(informative) or off or any(stands_out(w) < QUIET_MARGIN for w in on):
        return ''
    centres = [w.centre_ns for w in windows]  # on the camera's timeline: one line's offset moves them alike
    half = float(np.median(np.diff(centres))) / 2 if len(centres) > 1 else 0.0  # windows of one length, abutting
    first = (min(w.centre_ns for w in on) - centres[0]) / 1e9
    last = (max(w.centre_ns for w in on) - centres[0] + 2 * half) / 1e9
    need = max(min_agreeing, math.ceil(min_share * n_inf))
    return (f'{QUIET_OUTSIDE} {first:.1f}-{last:.1f} s: the {len(on)} windows there agree on one offset, the '
            f'other {len(informative) - len(on)} with a peak are faint or have none that stands out of its rivals '
            f'(little motion both cameras see); agreement needs {need}{STRETCH_ADVICE}')


def spread(resid: npt.NDArray[np.float64], var: npt.NDArray[np.float64]) -> float:
    """The weighted standard deviation of the agreeing windows about their line, sqrt(sum w r^2 /
    sum w) with w = 1 / var: a systematic term, not divided by the number of windows (0 for fewer
    than two). The windows of one scene share what two cameras see differently (other pixel grids,
    slow edges, another make's response), so it does not average away as their noise does
    (docs/studies.md, "Response lag between makes, and slow motion")."""
    if resid.size < 2:
        return 0.0
    w = 1.0 / var
    return math.sqrt(float(np.sum(w * resid * resid) / np.sum(w)))


@functools.lru_cache(maxsize=128)
def t_critical(dof: int, sigmas: float = SKEW_SIGNIFICANCE) -> float:
    """The value Student's t with ``dof`` degrees of freedom exceeds in absolute value as rarely as a
    normal variable exceeds ``sigmas`` (inf for no degree of freedom). Substituting x = sqrt(dof) tan u,
    the tail is an integral of cos(u) ** (dof - 1) over a finite range (Simpson's rule), solved for
    its end by bisection."""
    if dof <= 0:
        return math.inf
    tail = math.erfc(sigmas / math.sqrt(2))
    k = math.exp(math.lgamma((dof + 1) / 2) - math.lgamma(dof / 2)) / math.sqrt(math.pi)
    steps = 2000

    def beyond(u0: float) -> float:  # P(|t| > sqrt(dof) tan(u0))
        u = np.linspace(u0, math.pi / 2, steps + 1)
        f = np.cos(u) ** (dof - 1)
        h = (math.pi / 2 - u0) / steps
        return 2 * k * h / 3 * float(f[0] + f[-1] + 4 * f[1:-1:2].sum() + 2 * f[2:-1:2].sum())

    lo, hi = 0.0, math.pi / 2
    for _ in range(60):
        mid = (lo + hi) / 2
        if beyond(mid) > tail:
            lo = mid
        else:
            hi = mid
    return math.sqrt(dof) * math.tan((lo + hi) / 2)


def _candidate_lines(xs: npt.NDArray[np.float64], y: npt.NDArray[np.float64], max_skew_ppm: float
                     ) -> list[tuple[tuple[float, float], tuple[int, int]]]:
    """(offset at x = 0, slope) and the windows it goes through: constant lines through each window,
    and lines through pairs no steeper than ``max_skew_ppm`` (all neighbours, then a seeded sample)."""
    n = y.size
    out: list[tuple[tuple[float, float], tuple[int, int]]] = [((float(y[i]), 0.0), (i, i)) for i in range(n)]
    if max_skew_ppm <= 0 or n < 3:
        return out
    pairs = {(i, j) for i in range(n) for j in (i + 1, i + 2) if j < n}
    total = n * (n - 1) // 2
    if total <= MAX_PAIRS:
        pairs |= {(i, j) for i in range(n) for j in range(i + 1, n)}
    else:
        rng = np.random.default_rng(n)
        while len(pairs) < MAX_PAIRS:
            i, j = sorted(rng.choice(n, 2, replace=False).tolist())
            pairs.add((i, j))
    limit = max_skew_ppm * 1e-6
    for i, j in sorted(pairs):
        dx = xs[j] - xs[i]
        if dx == 0:
            continue
        slope = float((y[j] - y[i]) / dx)
        if abs(slope) <= limit:
            out.append(((float(y[i] - slope * xs[i]), slope), (i, j)))
    return out


def _pair_line_sd(xs: npt.NDArray[np.float64], sd: npt.NDArray[np.float64], i: int, j: int, sloped: bool
                  ) -> npt.NDArray[np.float64]:
    """The standard error, at every window, of a line drawn through windows i and j (the same one for
    a constant line)."""
    if not sloped or i == j:
        return np.full(xs.size, sd[i])
    span = xs[j] - xs[i]
    u = (xs - xs[i]) / span  # 0 at i, 1 at j
    return np.sqrt(((1 - u) * sd[i]) ** 2 + (u * sd[j]) ** 2)


def _refit_inliers(xs: npt.NDArray[np.float64], y: npt.NDArray[np.float64], var: npt.NDArray[np.float64],
                   start: npt.NDArray[np.bool_], *, drift: bool, rounds: int = 5) -> npt.NDArray[np.bool_]:
    """From the windows ``start``: a line fitted to them (weighted), and the windows within SIGMAS of
    it (their errors and the line's), until the set settles."""
    inl = start
    for _ in range(rounds):
        if inl.sum() < 2:
            return inl
        a2, b2, xc, se_a, se_b, _ = _weighted_line(xs[inl], y[inl], var[inl], slope=drift)
        line_var = se_a * se_a + (0.0 if not math.isfinite(se_b) else (se_b * (xs - xc)) ** 2)
        pred = a2 + b2 * (xs - xc)
        new = np.abs(y - pred) <= SIGMAS * np.sqrt(var + line_var)
        if np.array_equal(new, inl):
            break
        inl = new
    return inl


def _chance(x: npt.NDArray[np.float64], se: npt.NDArray[np.float64], n_inf: int, search_ns: int,
            max_skew_ppm: float) -> float:
    """A bound on the probability that as many of ``n_inf`` windows as agree here (centres ``x``,
    errors ``se``) would agree by accident, were each window's offset anywhere in the search range.

    The most precise agreeing window places the line; every other lands within its tolerance of it
    (SIGMAS of both errors, widened by the slope the line may take over their distance) with
    probability that tolerance over the range. A union bound counts the window that places it and
    the windows that join it."""
    n = se.size
    if n < 2:
        return 1.0
    ways = n_inf * math.comb(n_inf - 1, n - 1)
    return float(min(1.0, ways * _landing(x, se, search_ns, max_skew_ppm)))


def _landing(x: npt.NDArray[np.float64], se: npt.NDArray[np.float64], search_ns: int, max_skew_ppm: float) -> float:
    """The probability that, the most precise of these windows placing a line, every other lands
    within its tolerance of it by accident (``_chance``, one way to pick them)."""
    d = int(np.argmin(se))
    tol = SIGMAS * np.sqrt(se * se + se[d] * se[d]) + max_skew_ppm * 1e-6 * np.abs(x - x[d])
    p = np.minimum(1.0, 2 * tol / max(search_ns, 1))
    return math.prod(np.delete(p, d).tolist())


def _step(xs: npt.NDArray[np.float64], y: npt.NDArray[np.float64], sd: npt.NDArray[np.float64],
          on_line: npt.NDArray[np.bool_], clear: Sequence[Evidence], y0: int, a: float, b: float, xc: float,
          search_ns: int, lobe_ns: int, chance_limit: float) -> tuple[int, int, float] | None:
    """(first, last, shift from the line) of a run of consecutive windows with a clear peak (``xs``,
    ``y``, ``sd``, ``clear``: those windows; ``y`` about ``y0``) that lie off the line, not even on
    its peak (``on_line``), and agree among themselves on one offset so closely that they would by
    accident with probability under ``chance_limit``: a clock that jumped, which one line cannot
    hold. A run is not counted when a window of it also has a coarse peak on the line, apart from
    its own (its scene repeats, and the ambiguity check judges it). The longest such run, else None."""
    found: tuple[int, int, float] | None = None
    n = y.size
    i = 0
    while i < n:
        if on_line[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and not on_line[j + 1]:
            j += 1
        for first in range(i, j):  # the longest agreeing stretch from each start
            if found is not None and j - first <= found[1] - found[0]:
                break  # no longer one can start here
            last, level = first, 0.0
            for end in range(first + 1, j + 1):
                part = slice(first, end + 1)
                w = 1.0 / (sd[part] ** 2)
                mu = float(np.sum(w * y[part]) / np.sum(w))
                se_mu = math.sqrt(1.0 / float(np.sum(w)))
                if not np.all(np.abs(y[part] - mu) <= SIGMAS * np.sqrt(sd[part] ** 2 + se_mu * se_mu)):
                    break
                last, level = end, mu
            if last == first or (found is not None and last - first <= found[1] - found[0]):
                continue
            run = slice(first, last + 1)
            if any(abs(c - (y0 + a + b * (xs[k] - xc))) <= lobe_ns < abs(c - clear[k].offset_ns)
                   for k in range(first, last + 1) for c, _ in clear[k].candidates):
                continue
            # the ways to pick a run of consecutive windows: where it starts
            if (n - (last - first)) * _landing(xs[run], sd[run], search_ns, 0.0) <= chance_limit:
                found = (first, last, level - (a + b * (float(np.mean(xs[run])) - xc)))
        i = j + 1
    return found


def _ambiguity(windows: Sequence[Evidence], a: float, b: float, anchor: float, lobe_ns: int
               ) -> tuple[float, int] | None:
    """(shift, windows) of the best-supported other offset among the agreeing windows' candidates,
    when it is ambiguous (AMBIGUOUS_SHARE of them, each nearly as high as its best), else None."""
    shifts = []
    for w in windows:
        if not w.candidates:
            continue
        top = w.candidates[0][1]
        at = a + b * (w.centre_ns - anchor)
        shifts.append([c - at for c, v in w.candidates if abs(c - at) > lobe_ns and v >= AMBIGUOUS_HEIGHT * top])
    if not windows:
        return None
    flat = sorted(s for part in shifts for s in part)
    best: tuple[float, int] | None = None
    for s in flat:
        count = sum(any(abs(v - s) <= lobe_ns / 2 for v in part) for part in shifts)
        if best is None or count > best[1]:
            best = (s, count)
    if best is not None and best[1] >= AMBIGUOUS_SHARE * len(windows):
        return best
    return None
