"""The estimator beyond the paper: windows searched over the whole range with only covered bins
paired, refined to microseconds with a jackknife standard error, and accepted only when independent
windows agree (``agreement``). numpy only; times are int64 ns on each camera's own timeline. How it
works: docs/method.md, "The refined method".
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from evsync_ros.core.agreement import Agreement, Evidence, agree
from evsync_ros.core.bins import BinnedStream, GridCounts, SortedTimes
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.density import FloatArray, TimeArray, check_positive_int, paired_offset_ns
from evsync_ros.core.errors import ParameterError
from evsync_ros.core.results import CameraFit, WindowFit
from evsync_ros.core.schedule import coverage, window_length_ns

JACKKNIFE_BLOCKS = 10
"""Blocks a window is cut into for its offset's jackknife standard error."""
JACKKNIFE_DELETE = 3
"""Blocks each replicate of the jackknife leaves out (a delete-d jackknife, ``_peak``)."""
REPLICATES = np.array([[0.0 if k in left_out else 1.0 for k in range(JACKKNIFE_BLOCKS)]
                       for left_out in itertools.combinations(range(JACKKNIFE_BLOCKS), JACKKNIFE_DELETE)])
"""The jackknife's replicates, rows of 0 and 1 over the blocks (1: kept): every way to leave
``JACKKNIFE_DELETE`` of them out (120; each block left out by 36)."""
REPLICATES.flags.writeable = False
CANDIDATES = 3
"""Coarse peaks each window keeps (the best first), for the ambiguity check."""
MODEL_SYSTEMATIC_NS = 250_000
"""What a difference of camera models adds to a camera's offset error, unless its latency is known:
cameras of different models respond to the same edge with different delays (a slower photoreceptor,
a higher threshold), which no density method can tell from a clock offset; on the simulator the
DAVIS-like camera trails the Prophesee-like reference by 0.3-0.45 ms (studies/pixel_lag.py).
Front ends that can tell models apart (the message type, encoding or geometry differ) add it."""


@dataclass(frozen=True)
class RefinedParams:
    """Parameters of the refined estimator."""

    tau_ns: int = 1_000_000
    """Coarse bin width (1 ms, as the paper)."""
    window_ns: int = 10_000_000_000
    """The longest window (the paper's T, 10 s): long recordings are cut into windows of this."""
    min_window_ns: int = 250_000_000
    """The shortest window: short recordings get windows down to this, to have several."""
    windows_wanted: int = 5
    """Windows a recording should give at least, when windows no shorter than ``min_window_ns`` allow."""
    max_shift_ns: int = 5_000_000_000
    """Search half-range S around the prior offset."""
    min_overlap: float = 0.5
    """Least fraction of a window's covered bins a candidate lag must pair with covered camera bins."""
    fine_ns: int = 100_000
    """Fine bin width of the refinement (100 us)."""
    smooth_ns: int | tuple[int, ...] = (150_000, 500_000, 1_500_000, 3_000_000)
    """Gaussian sigmas the refinement tries on the camera's fine counts (an int is one). Each gives an
    offset and its jackknife standard error; the window takes the most precise one that agrees with
    the broadest (which a narrow smoothing's spurious fine peak does not)."""
    lobe_margin_ns: int = 20_000_000
    """Rival peaks and candidates are sought outside the main lobe widened by this much."""
    min_confidence: float = 0.5
    """The least share of the windows with a clear peak that must agree on a camera's line."""
    drift: bool = True
    """Fit a skew through the agreeing windows (else their offsets are one constant)."""
    gap_ns: int = 500_000_000
    """A stream with no event for this long has no data there (a late start, a pause, a drop-out)."""
    max_skew_ppm: float = 150.0
    """Lines steeper than this are not tried (two crystal clocks seldom differ by 100 ppm); it also
    bounds how far apart windows may agree by accident, so a generous bound costs evidence."""
    min_agreeing: int = 3
    """Windows that must agree, at least."""
    max_uncertainty_ns: int = 1_000_000
    """An offset known less precisely than this (standard error) is not accepted."""
    chance: float = 1e-3
    """Agreement that could happen by accident with more than this probability is not accepted."""
    chance_search_ns: int = 0
    """The range a window's peak is judged to land in by accident (0: the search's, 2 ``max_shift_ns``);
    wider where the search was centred on what the windows' own peaks chose (``evidence.vote``)."""
    window_floor_ns: int = 10_000
    """Added in quadrature to each window's standard error (the refinement's own resolution)."""
    systematic_ns: int = 20_000
    """Added in quadrature to each camera's offset error: what averaging windows cannot take away
    (two cameras' views of one scene differ: a lag of tens of microseconds between same-model
    cameras is common on the simulator, docs/studies.md)."""

    def __post_init__(self) -> None:
        for name in ('tau_ns', 'window_ns', 'min_window_ns', 'windows_wanted', 'max_shift_ns', 'fine_ns',
                     'lobe_margin_ns', 'gap_ns', 'min_agreeing', 'max_uncertainty_ns'):
            check_positive_int(getattr(self, name), name=name)
        for name in ('window_floor_ns', 'systematic_ns'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise ParameterError(f'{name} must be a non-negative integer, got {value!r}')
        sigmas = self._smooth_tuple
        if not sigmas:
            raise ParameterError('smooth_ns must be a sigma or a tuple of sigmas (ns), got ()')
        for sigma in sigmas:
            check_positive_int(sigma, name='smooth_ns')
        if self.window_ns % self.tau_ns or self.min_window_ns % self.tau_ns or self.tau_ns % self.fine_ns:
            raise ParameterError('window_ns and min_window_ns must be whole numbers of tau_ns, and tau_ns of fine_ns')
        if self.min_window_ns > self.window_ns:
            raise ParameterError(f'min_window_ns ({self.min_window_ns}) must not exceed window_ns ({self.window_ns})')
        if not (isinstance(self.min_overlap, (int, float)) and 0 < self.min_overlap <= 1):
            raise ParameterError(f'min_overlap must be in (0, 1], got {self.min_overlap!r}')
        if not (isinstance(self.min_confidence, (int, float)) and 0 <= self.min_confidence <= 1):
            raise ParameterError(f'min_confidence must be in [0, 1], got {self.min_confidence!r}')
        for name in ('max_skew_ppm', 'chance'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ParameterError(f'{name} must be a finite non-negative number, got {value!r}')

    @property
    def refine_reach_ns(self) -> int:
        """How far beyond a window, either side of its coarse offset, the refinement reads the camera:
        the broadest smoothing's reach (``_sigma_reach_ns``, on that smoothing's own bins)."""
        return max(_sigma_reach_ns(sigma, self) for sigma in self.sigmas_ns)

    @property
    def camera_reach_ns(self) -> int:
        """How far beyond a window, either side of its prior, a window's fit reads the camera: the
        search half-range, then the refinement's reach around the coarse offset."""
        return self.max_shift_ns + self.refine_reach_ns

    @property
    def sigmas_ns(self) -> tuple[int, ...]:
        """The smoothing sigmas to try, narrowest first."""
        return tuple(sorted({int(v) for v in self._smooth_tuple}))

    @property
    def _smooth_tuple(self) -> tuple[int, ...]:
        """``smooth_ns`` as given, one sigma or several, as a tuple."""
        return self.smooth_ns if isinstance(self.smooth_ns, tuple) else (self.smooth_ns,)

    def window_length(self, span_ns: int, *, tile: bool = True) -> int:
        """The window length for a span of the reference's events (``schedule.window_length_ns``;
        ``tile``: the span is known whole and the windows fill it)."""
        return window_length_ns(span_ns, window_ns=self.window_ns, min_window_ns=self.min_window_ns,
                                windows_wanted=self.windows_wanted, tau_ns=self.tau_ns, tile=tile)


# --- correlation ---------------------------------------------------------------------------------

@functools.lru_cache(maxsize=256)
def fft_size(n: int) -> int:
    """The smallest 5-smooth number (2^i 3^j 5^k, fast for the FFT) not below ``n`` (cached: a rig asks
    for a few sizes over and over)."""
    best = 1 << max(0, (n - 1).bit_length())
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            p2 = p35
            while p2 < n:
                p2 *= 2
            best = min(best, p2)
            p35 *= 3
        p5 *= 5
    return best


def ncc_all_lags(a: FloatArray, b: FloatArray, *, lags: int | None = None) -> tuple[FloatArray, FloatArray]:
    """Pearson correlation of a[i] with b[i + m] over each lag's own overlap, for m = 0 .. lags - 1
    (default: every lag, len(b)).

    Returns (ncc, overlap): overlap[m] is how many samples of ``a`` lag m pairs. ``a`` must not be
    longer than ``b``. NaN where either side is constant over the overlap.

    Lag m pairs a[:k] with b[m:m + k], k = min(len(a), len(b) - m), so every sum but the cross
    term is a difference of prefix sums; the cross term is one correlation by FFT.
    """
    return masked_ncc(a, np.ones(a.size, dtype=bool), b, np.ones(b.size, dtype=bool), lags=lags)


def masked_ncc(a: FloatArray, ma: npt.NDArray[np.bool_], b: FloatArray, mb: npt.NDArray[np.bool_], *,
               lags: int | None = None) -> tuple[FloatArray, FloatArray]:
    """``ncc_all_lags`` pairing only bins both masks cover: lag m's Pearson correlation is over the
    i where ``ma[i]`` and ``mb[i + m]``, and its overlap is how many such i there are. Sums over a
    side covered throughout are prefix sums; the rest are correlations by FFT."""
    n, nl = a.size, b.size if lags is None else min(lags, b.size)
    size = fft_size(max(b.size, n + nl - 1))  # no lag below nl wraps around
    fa, fb = ma.astype(np.float64), mb.astype(np.float64)
    a, b = a * fa, b * fb
    spectra: dict[str, np.ndarray] = {}

    def spectrum(name: str, x: FloatArray) -> np.ndarray:
        if name not in spectra:
            spectra[name] = np.fft.rfft(x, size)
        return spectra[name]

    def corr(x: str, xv: FloatArray, y: str, yv: FloatArray) -> FloatArray:
        return np.fft.irfft(np.conj(spectrum(x, xv)) * spectrum(y, yv), size)[:nl]

    def sliding(x: FloatArray) -> FloatArray:  # sum of x[m + i] over i < n (zero past its end)
        return _sliding_sums(np.pad(x, (0, max(0, n + nl - 1 - x.size))), n, nl)

    a_all, b_all = bool(ma.all()), bool(mb.all())
    if a_all and b_all:
        count = np.minimum(n, b.size - np.arange(nl)).astype(np.float64)
        ca, caa = np.concatenate([[0.0], np.cumsum(a)]), np.concatenate([[0.0], np.cumsum(a * a)])
        idx = count.astype(np.int64)
        sa, saa = ca[idx], caa[idx]
    elif a_all:
        count = np.rint(sliding(fb))
        sa, saa = corr('a', a, 'mb', fb), corr('aa', a * a, 'mb', fb)
    else:
        count = np.rint(corr('ma', fa, 'mb', fb))
        sa, saa = corr('a', a, 'mb', fb), corr('aa', a * a, 'mb', fb)
    if a_all:
        sb, sbb = sliding(b), sliding(b * b)
    else:
        sb, sbb = corr('ma', fa, 'b', b), corr('ma', fa, 'bb', b * b)
    sab = corr('a', a, 'b', b)
    with np.errstate(invalid='ignore', divide='ignore'):
        cov = sab - sa * sb / count
        va = saa - sa * sa / count
        vb = sbb - sb * sb / count
        ncc = cov / np.sqrt(va * vb)
        tiny_a = 1e-9 * max(_sumsq(a), 1e-300)
        tiny_b = 1e-9 * max(_sumsq(b), 1e-300)
        ncc[(va <= tiny_a) | (vb <= tiny_b) | (count < 2)] = np.nan
    return ncc, count


def _sumsq(x: FloatArray) -> float:
    """sum(x^2), without BLAS (whose thread pool, woken by a long dot product, spins on every core)."""
    return float(np.einsum('i,i->', x, x))


class Counts(Protocol):
    """Where a window's counts come from: a sorted array held whole, a stream's bins, a snapshot."""

    @property
    def first_ns(self) -> int | None: ...

    @property
    def last_ns(self) -> int | None: ...

    def counts(self, start_ns: int, bin_ns: int, n: int) -> FloatArray: ...


def _source(x: TimeArray | Counts) -> Counts:
    return x if isinstance(x, (SortedTimes, BinnedStream, GridCounts)) else SortedTimes(np.asarray(x))


def _half_width(sigma_bins: float) -> int:
    return max(1, math.ceil(3 * sigma_bins))


@functools.lru_cache(maxsize=32)
def _gaussian(sigma_bins: float) -> FloatArray:
    half = _half_width(sigma_bins)
    x = np.arange(-half, half + 1)
    k = np.exp(-0.5 * (x / sigma_bins) ** 2)
    k /= k.sum()
    k.flags.writeable = False  # shared (cached)
    return k


def _confidence(ncc: FloatArray, best: int, lobe_margin: int) -> tuple[float, float, int, int]:
    """(peak, confidence, lobe start, lobe end): the main lobe is where the curve stays above half
    the peak around ``best``; confidence = peak - the best rival outside the lobe widened by
    ``lobe_margin`` bins, in [0, 1]."""
    peak = float(ncc[best])
    if not peak > 0:
        return peak, 0.0, best, best
    half = peak / 2
    lo = best
    while lo > 0 and not (ncc[lo - 1] < half):  # NaN counts as part of nothing
        lo -= 1
        if math.isnan(ncc[lo]):
            break
    hi = best
    while hi < ncc.size - 1 and not (ncc[hi + 1] < half):
        hi += 1
        if math.isnan(ncc[hi]):
            break
    outside = np.concatenate([ncc[: max(0, lo - lobe_margin)], ncc[hi + lobe_margin + 1:]])
    outside = outside[~np.isnan(outside)]
    rival = float(outside.max()) if outside.size else 0.0
    return peak, max(0.0, min(1.0, peak - max(rival, 0.0))), lo, hi


def _candidates(ncc: FloatArray, lags: npt.NDArray[np.int64], lo: int, hi: int, margin: int
                ) -> list[tuple[int, float]]:
    """(lag, ncc) of the best ``CANDIDATES`` peaks, each outside the others' lobes widened by ``margin``."""
    curve = ncc.copy()
    out = []
    width = max(hi - lo, 0) // 2 + margin
    for _ in range(CANDIDATES):
        if np.all(np.isnan(curve)):
            break
        m = int(np.nanargmax(curve))
        out.append((int(lags[m]), float(curve[m])))
        curve[max(0, m - width):m + width + 1] = np.nan
    return out


# --- one window ----------------------------------------------------------------------------------

def fit_window(ref: TimeArray | Counts, cam: TimeArray | Counts, *, ref_start_ns: int, length_ns: int,
               prior_ns: int, params: RefinedParams) -> WindowFit:
    """One window of the camera against the reference: the coarse search over every lag in
    [-S, S] around ``prior_ns`` pairing only covered bins, the best few coarse peaks, and the best
    one refined to microseconds with its jackknife standard error (docs/method.md).

    Args:
        ref, cam: the reference's and the camera's events (sorted times, or binned counts). ``cam``
            holds the camera's times already mapped by everything but the offset sought (a skew
            correction, on a second pass). Binned streams need ``ref_start_ns`` and
            ``ref_start_ns - prior_ns`` on their grids.
        ref_start_ns, length_ns: the window on the reference timeline.
        prior_ns: the offset the search is centred on.
        params: the estimator's parameters.

    Returns:
        The ``WindowFit``; ``has_data`` false when no lag pairs enough covered bins, and ``se_ns`` inf
        when the window has no clear peak.
    """
    p = params
    src_ref, src_cam = _source(ref), _source(cam)
    tau = p.tau_ns
    n = length_ns // tau
    s = p.max_shift_ns // tau
    a = src_ref.counts(ref_start_ns, tau, n)
    cam_start = ref_start_ns - prior_ns - s * tau
    b = src_cam.counts(cam_start, tau, n + 2 * s)
    ma = coverage(a, start_ns=ref_start_ns, bin_ns=tau, first_ns=src_ref.first_ns, last_ns=src_ref.last_ns,
                  gap_ns=p.gap_ns)
    mb = coverage(b, start_ns=cam_start, bin_ns=tau, first_ns=src_cam.first_ns, last_ns=src_cam.last_ns,
                  gap_ns=p.gap_ns)
    # camera bin i + m pairs reference bin i: lag m's offset, less the prior (increasing m, decreasing lag)
    lags = paired_offset_ns(ref_start_ns=ref_start_ns, cam_start_ns=cam_start, bin_ns=tau,
                            bins_apart=-np.arange(2 * s + 1, dtype=np.int64)) - prior_ns
    covered = int(ma.sum())
    empty = WindowFit(ref_start_ns=ref_start_ns, length_ns=length_ns, offset_ns=prior_ns, peak=math.nan,
                      confidence=0.0, accepted=False, se_ns=math.inf, has_data=False, prior_ns=prior_ns,
                      lags_ns=lags[::-1].copy(), ncc=np.full(lags.size, np.nan), ref_counts=a, cam_counts=b)
    if covered < p.min_overlap * n or not mb.any() or a.sum() == 0 or b.sum() == 0:
        return empty
    ncc, count = masked_ncc(a, ma, b, mb, lags=lags.size)  # lags within [-S, S]
    ncc[count < p.min_overlap * covered] = np.nan
    lags, ncc, count = lags[::-1].copy(), ncc[::-1].copy(), count[::-1].copy()  # increasing lag
    if np.all(np.isnan(ncc)):
        return replace(empty, lags_ns=lags, ncc=ncc)
    best = int(np.nanargmax(ncc))
    peak, confidence, lo, hi = _confidence(ncc, best, p.lobe_margin_ns // tau)
    candidates = tuple((prior_ns + lag, value)
                       for lag, value in _candidates(ncc, lags, lo, hi, p.lobe_margin_ns // tau))
    coarse = prior_ns + int(lags[best])
    m = s - (coarse - prior_ns) // tau
    span = _covered_span(ma, mb, m, min_bins=math.ceil(p.min_overlap * n))
    refined: tuple[tuple[int, int, float], ...] = ()
    if span is not None and peak > 0:
        start = ref_start_ns + span[0] * tau
        refined = tuple((sigma, offset, math.hypot(se, p.window_floor_ns) if math.isfinite(se) else math.inf)
                        for sigma, offset, se in _refine(src_ref, src_cam, start_ns=start,
                                                         n_fine=(span[1] - span[0]) * (tau // p.fine_ns),
                                                         coarse_ns=coarse, params=p,
                                                         spans=_recorded_spans(mb, m, span, p)))
    sigma, offset, se = min(refined, key=lambda r: r[2], default=(0, coarse, math.inf))
    return WindowFit(ref_start_ns=ref_start_ns, length_ns=length_ns, offset_ns=offset, peak=peak,
                     confidence=confidence, accepted=False, se_ns=se, smooth_ns=sigma, candidates=candidates,
                     refined=refined, has_data=True, prior_ns=prior_ns, lags_ns=lags, ncc=ncc, ref_counts=a,
                     cam_counts=b)


def _smoothing_grid(sigma: int, params: RefinedParams) -> tuple[int, int, int]:
    """(bin width, lags either side of the coarse peak, kernel half-width), the last two in those
    bins, of the refinement under smoothing ``sigma``: lags within two coarse bins of the coarse
    peak, a Gaussian kernel of 3 sigma either side."""
    bw = smoothing_bin_ns(sigma, params.fine_ns)
    return bw, -(-2 * params.tau_ns // bw), _half_width(sigma / bw)


def _sigma_reach_ns(sigma: int, params: RefinedParams) -> int:
    """How far either side of a reference bin the refinement reads the camera under smoothing
    ``sigma``: its lags and its kernel's half-width."""
    bw, reach, pad = _smoothing_grid(sigma, params)
    return (reach + pad) * bw


def _recorded_spans(mb: npt.NDArray[np.bool_], m: int, span: tuple[int, int], params: RefinedParams
                    ) -> dict[int, tuple[int, int]]:
    """Per smoothing, the part of the covered ``span`` (reference coarse bins, b[i + m] pairing a[i])
    whose camera neighbourhood, to that smoothing's reach, lies within the camera's recording, as
    (first fine bin from the span's start, fine bins).

    The refinement reads the camera up to its reach either side of each reference bin. A bin whose
    neighbourhood runs past the camera's first or last event, or into a gap, would pair with empty
    bins read as no activity: a slope that pulled the broad smoothings' peaks by up to 1.8 ms where
    both recordings start mid-activity (test_refined.py). Each smoothing drops only what its own
    reach needs."""
    tau, q = params.tau_ns, params.tau_ns // params.fine_ns
    i0, i1 = span
    holes = np.flatnonzero(~mb)  # the camera's coverage runs [c0, c1) that holds the span's bins
    c0 = int(holes[holes < i0 + m].max(initial=-1)) + 1
    later = holes[holes >= i1 + m]
    c1 = int(later.min()) if later.size else mb.size
    out = {}
    for sigma in params.sigmas_ns:
        k = -(-_sigma_reach_ns(sigma, params) // tau)
        first, last = max(i0, c0 - m + k), min(i1, c1 - m - k)
        if last > first:
            out[sigma] = ((first - i0) * q, (last - first) * q)
    return out


def _covered_span(ma: npt.NDArray[np.bool_], mb: npt.NDArray[np.bool_], m: int, *, min_bins: int
                  ) -> tuple[int, int] | None:
    """The longest run [i0, i1) of reference bins covered on both sides at coarse lag index ``m``
    (b[i + m] pairs a[i]), when it is at least ``min_bins`` long."""
    both = ma & mb[m:m + ma.size]
    if not both.any():
        return None
    edges = np.diff(np.concatenate(([0], both.view(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    k = int(np.argmax(ends - starts))
    if ends[k] - starts[k] < min_bins:
        return None
    return int(starts[k]), int(ends[k])


def _refine(ref: Counts, cam: Counts, *, start_ns: int, n_fine: int, coarse_ns: int, params: RefinedParams,
            spans: Mapping[int, tuple[int, int]]) -> list[tuple[int, int, float]]:
    """(sigma, offset, jackknife standard error) near ``coarse_ns`` from counts over [start_ns,
    start_ns + n_fine fine bins), for each sigma of ``params.smooth_ns``: it smooths the camera's
    counts, a parabola through the peak of the correlation gives the offset, and a jackknife over
    ``JACKKNIFE_BLOCKS`` blocks of the window its standard error (inf when the peak is not within
    reach of the coarse one). A broad smoothing is computed on bins 0.4 of its sigma wide
    (``smoothing_bin_ns``): the parabola's bias stays under 0.3 % of sigma, for a fraction of the
    work. Which smoothing a camera uses is decided over all its windows (``camera_result``).
    ``spans``: per smoothing, the part of the fine bins it uses, as (first, count)
    (``_recorded_spans``; a smoothing left out is not tried)."""
    p = params
    f = p.fine_ns
    plans = []
    for sigma in p.sigmas_ns:
        off, count = spans.get(sigma, (0, 0))
        bw, reach, pad = _smoothing_grid(sigma, p)
        q = bw // f
        n = count // q
        if n >= 4 * JACKKNIFE_BLOCKS:
            plans.append((sigma, bw, q, n, reach, pad, off))
    if not plans:
        return []
    # fine counts once over the widest extent; each smoothing sums them into its own bins
    extent = max((reach + pad) * q for _, _, q, _, reach, pad, _ in plans)  # fine bins either side
    a_fine = ref.counts(start_ns, f, n_fine)
    raw_fine = cam.counts(start_ns - coarse_ns - extent * f, f, n_fine + 2 * extent)
    if not a_fine.any() or not raw_fine.any():
        return []
    results = []
    for sigma, bw, q, n, reach, pad, off in plans:
        first = extent + off - (reach + pad) * q
        a = _binned(a_fine[off:off + n * q], q)
        raw = _binned(raw_fine[first:first + (n + 2 * (reach + pad)) * q], q)
        # b[i + l] pairs a[i] at offset coarse + (reach - l) bw, l = 0 .. 2 reach
        b = np.convolve(raw, _gaussian(sigma / bw), mode='valid')  # raw's pad either side dropped
        peak = _peak(a, b, n, 2 * reach + 1)
        if peak is None:
            continue
        m, frac, se = peak
        if m in (0, 2 * reach):  # the peak is not within reach of the coarse one
            results.append((sigma, coarse_ns, math.inf))
            continue
        results.append((sigma, int(round(coarse_ns + (reach - m - frac) * bw)), se * bw))
    return results


def smoothing_bin_ns(sigma_ns: int, fine_ns: int) -> int:
    """The bin width a smoothing of ``sigma_ns`` is computed on: ``fine_ns``, or the multiple of it
    nearest below sigma / 2.5 (a parabola through a Gaussian peak sampled at 0.4 sigma is off by
    at most 0.3 % of sigma; its kernel stays 17 bins long)."""
    return fine_ns * max(1, int(sigma_ns / (2.5 * fine_ns)))


def _binned(x: FloatArray, q: int) -> FloatArray:
    """Sums of ``q`` consecutive values (``x.size`` a multiple of ``q``)."""
    if q == 1:
        return x
    out = x[0::q].copy()
    for k in range(1, q):
        out += x[k::q]
    return out


def _peak(a: FloatArray, b: FloatArray, n: int, lags: int) -> tuple[int, float, float] | None:
    """(lag, its parabola's fraction, jackknife standard error in lags) of the peak of the Pearson
    correlation of a[i] with b[i + l], l = 0 .. lags - 1, over i < n; None when either side is flat.

    The error is a delete-d jackknife (Shao and Wu) over ``JACKKNIFE_BLOCKS`` blocks of i: each
    replicate (``REPLICATES``) leaves ``JACKKNIFE_DELETE`` blocks out and seeks its own peak over all
    the lags, and the variance is (blocks - d) / d times their mean squared spread. A peak's position
    is not a smooth statistic: leave-one-block-out replicates, sharing 90 % of the data, stay on the
    window's own noise bump, and with one camera's events jittered by 1 ms they understated the
    narrowest smoothing's error four-fold on the EVK4 recording (rms of error / standard error over
    100 windows: 4.1, leaving 3 out: 1.36; ``studies/jackknife.py``). Leaving half out (d = 5)
    overstates it more where one burst carries a window: the replicates without it wander."""
    a, b = a[:n], b[:n + lags - 1]
    bb = b * b
    # each block's sums at every lag (the whole window's are their totals) ...
    pairs, starts, ends, sizes = _blocks(n)
    bsab = np.stack([np.correlate(b[s:e + lags - 1], a[s:e], 'valid') for s, e in pairs], axis=1)  # (lags, blocks)
    bsa, bsaa = np.add.reduceat(a, starts), np.add.reduceat(a * a, starts)
    sa, saa = float(bsa.sum()), float(bsaa.sum())
    sb, sbb = _sliding_sums(b, n, lags), _sliding_sums(bb, n, lags)
    sab_all = bsab.sum(axis=1)
    scores = _pearson(n, sa, saa, sb, sbb, sab_all)
    if scores is None:
        return None
    m = int(np.argmax(scores))
    if m in (0, lags - 1):
        return m, 0.0, math.inf
    frac = _parabola(scores[m - 1], scores[m], scores[m + 1])
    # ... and each replicate's, the sum of the blocks it keeps
    bsb, bsbb = _block_sums(b, starts, ends, lags), _block_sums(bb, starts, ends, lags)
    k = REPLICATES
    r = _pearson(k @ sizes, k @ bsa, k @ bsaa, bsb @ k.T, bsbb @ k.T, bsab @ k.T)  # (lags, replicates)
    if r is None or not np.isfinite(r).all():
        return m, frac, math.inf
    i = np.argmax(r, axis=0)
    cols = np.arange(r.shape[1])
    last = lags - 1
    y0, y1, y2 = r[np.maximum(i - 1, 0), cols], r[i, cols], r[np.minimum(i + 1, last), cols]
    den = y0 - 2 * y1 + y2
    with np.errstate(invalid='ignore', divide='ignore'):
        shift = np.where((i > 0) & (i < last) & (den < 0), np.clip(0.5 * (y0 - y2) / den, -0.5, 0.5), 0.0)
    peaks = i + shift
    d = JACKKNIFE_DELETE
    return m, frac, math.sqrt((JACKKNIFE_BLOCKS - d) / d * float(np.mean((peaks - peaks.mean()) ** 2)))


def _sliding_sums(x: FloatArray, n: int, lags: int) -> FloatArray:
    """sum(x[l:l + n]) for l < lags: one sum, then what enters and leaves at each step (a prefix sum
    of the whole array costs as much as the correlation it serves)."""
    out = np.empty(lags)
    out[0] = x[:n].sum()
    np.cumsum(x[n:n + lags - 1] - x[:lags - 1], out=out[1:])
    out[1:] += out[0]
    return out


def _block_sums(x: FloatArray, starts: npt.NDArray[np.int64], ends: npt.NDArray[np.int64], lags: int) -> FloatArray:
    """sum(x[s + l:e + l]) for each block (s, e) of contiguous ``starts``/``ends`` from 0 to n, at
    each lag l < lags: shape (lags, blocks)."""
    out = np.empty((lags, starts.size))
    out[0] = np.add.reduceat(x[:int(ends[-1])], starts)
    step = np.arange(lags - 1)[:, None]
    np.cumsum(x[ends + step] - x[starts + step], axis=0, out=out[1:])
    out[1:] += out[0]
    return out


@functools.lru_cache(maxsize=64)
def _blocks(n: int) -> tuple[list[tuple[int, int]], npt.NDArray[np.int64], npt.NDArray[np.int64], FloatArray]:
    """The jackknife's blocks of ``n`` bins: (start, end) pairs, starts, ends, sizes (cached, read-only)."""
    edges = np.linspace(0, n, JACKKNIFE_BLOCKS + 1).astype(np.int64)
    starts, ends = edges[:-1], edges[1:]
    sizes = (ends - starts).astype(np.float64)
    for x in (starts, ends, sizes):
        x.flags.writeable = False
    return list(zip(starts.tolist(), ends.tolist())), starts, ends, sizes


def _pearson(n: Any, sa: Any, saa: Any, sb: Any, sbb: Any, sab: Any) -> Any:
    """Pearson correlation from sums (numpy broadcasting); None when ``a`` is flat or ``b`` is flat
    everywhere, -inf where ``b`` is."""
    var_a = saa - sa * sa / n
    positive = var_a > 0  # a bool for one window, an array for the jackknife's replicates
    if not (positive if isinstance(positive, bool) else positive.all()):
        return None
    var_b = sbb - sb * sb / n
    ok = var_b > 1e-12 * sbb
    if not ok.any():
        return None
    with np.errstate(invalid='ignore', divide='ignore'):
        r = (sab - sa * sb / n) / np.sqrt(var_a * var_b)
    r[~ok] = -np.inf
    return r


def _parabola(y0: float, y1: float, y2: float) -> float:
    """Where a parabola through (-1, y0), (0, y1), (1, y2) peaks, in [-0.5, 0.5] (0 when it does not)."""
    den = float(y0) - 2 * float(y1) + float(y2)
    if not den < 0:
        return 0.0
    return min(0.5, max(-0.5, 0.5 * (float(y0) - float(y2)) / den))


# --- one camera ----------------------------------------------------------------------------------

def window_starts(ref: TimeArray, params: RefinedParams, *, span_ns: int | None = None) -> tuple[list[int], int]:
    """(starts, length) of the windows over the reference's sorted events: whole windows tiling them
    from the first (``schedule.plan``), those that hold a reference event (a gap, a clock jump, a
    corrupt time is stepped over, not walked window by window); ``span_ns`` (default: the events'
    span) decides their length."""
    first, last = int(ref[0]), int(ref[-1])
    length = params.window_length(last - first + 1 if span_ns is None else span_ns)
    count = (last - first + 1) // length
    if count <= 0:
        return [], length
    k = (ref - np.int64(first)) // np.int64(length)  # sorted: the distinct ones are where it changes
    held = k[np.concatenate(([True], k[1:] != k[:-1]))]
    return [first + int(i) * length for i in held[held < count].tolist()], length


def with_smoothing(fit: WindowFit, sigma: int) -> WindowFit:
    """The window's offset and standard error under smoothing ``sigma`` (no clear peak if it has none)."""
    for s, offset, se in fit.refined:
        if s == sigma:
            return replace(fit, offset_ns=offset, se_ns=se, smooth_ns=sigma)
    return replace(fit, se_ns=math.inf, smooth_ns=sigma)


def evidence(fit: WindowFit) -> Evidence:
    """What the agreement reads of a window."""
    return Evidence(centre_ns=fit.ref_start_ns + fit.length_ns // 2 - fit.offset_ns, offset_ns=fit.offset_ns,
                    se_ns=fit.se_ns, candidates=fit.candidates, has_data=fit.has_data)


def camera_result(topic: str, fits: Sequence[WindowFit], params: RefinedParams, *, systematic_ns: float = 0.0,
                  skew_ppm: float = 0.0, anchor_ns: int = 0, skew_se_ppm: float = math.inf) -> CameraFit:
    """A camera's estimate from its windows by agreement (``agreement.agree``).

    Every smoothing the windows were refined with is tried on all of them (how far two cameras'
    events agree in time differs by rig and scene). Of the smoothings whose windows are accepted,
    the camera takes the most precise one that agrees with the next broader accepted one within 3
    standard errors: a narrow smoothing can read a spurious fine peak near the right coarse one,
    and a few windows can agree on it; a broader one does not share it. (Not the broadest: on real
    scenes its peaks lean, by up to a millisecond, towards the slow side of a lopsided correlation.)
    When none is accepted, the smoothing most windows agree under says why. The chance limit is
    shared among the smoothings.

    ``skew_ppm``, ``anchor_ns``, ``skew_se_ppm``: the skew the windows were binned with (a second
    pass) and its standard error, added to the residual skew the windows show (kept even when not
    significant, the skew being known; its error, when they show one, is the total's).
    ``systematic_ns``: a camera's own systematic error (a known difference of camera models), added
    to the estimator's in quadrature.
    """
    p = params
    sigmas = p.sigmas_ns
    tried: list[tuple[Agreement, list[WindowFit]]] = []
    for sigma in sigmas:
        smoothed = [with_smoothing(f, sigma) for f in fits]
        result = agree([evidence(f) for f in smoothed], search_ns=p.chance_search_ns or 2 * p.max_shift_ns,
                       lobe_ns=p.lobe_margin_ns,
                       min_agreeing=p.min_agreeing, min_share=p.min_confidence, chance_limit=p.chance / len(sigmas),
                       max_uncertainty_ns=p.max_uncertainty_ns, max_skew_ppm=p.max_skew_ppm, drift=p.drift,
                       floor_ns=0.0, systematic_ns=math.hypot(p.systematic_ns, systematic_ns),
                       near_ns=2 * p.tau_ns,  # the refinement's reach about a coarse peak
                       skew_known=bool(skew_ppm))
        tried.append((result, smoothed))
    accepted = [t for t in tried if t[0].accepted]
    stepped = [t for t in tried if t[0].stepped]
    if stepped:
        # a clock step seen under any smoothing is the camera's, not the smoothing's (the chance limit
        # is shared among them): no one line holds the recording, whatever the others accept
        result, smoothed = stepped[0]
    elif accepted:
        # each accepted smoothing checked against the next broader accepted one (the broadest needs
        # none): a narrow smoothing can read a spurious fine peak that a broader one does not share;
        # the broadest of all is no judge, its peaks lean towards the heavier side of a lopsided
        # correlation (real scenes: sharp onsets, slow decays)
        consistent = [t for t, broader in zip(accepted, accepted[1:])
                      if abs(_line_value(t[0], broader[0].anchor_ns) - broader[0].offset_ns)
                      <= 3 * math.hypot(t[0].se_ns, broader[0].se_ns)] + accepted[-1:]
        result, smoothed = min(consistent, key=lambda t: t[0].se_ns)
    else:
        result, smoothed = max(tried, key=lambda t: sum(t[0].agreeing))
    return _camera(topic, smoothed, result, p, skew_ppm=skew_ppm, anchor_ns=anchor_ns, skew_se_ppm=skew_se_ppm)


def _line_value(result: Agreement, at_ns: int) -> float:
    """The offset an agreement's line gives at ``at_ns`` (camera timeline)."""
    return result.offset_ns + result.skew_ppm * 1e-6 * (at_ns - result.anchor_ns)


def _camera(topic: str, fits: Sequence[WindowFit], result: Agreement, params: RefinedParams, *, skew_ppm: float,
            anchor_ns: int, skew_se_ppm: float) -> CameraFit:
    marked = tuple(replace(f, accepted=ok) for f, ok in zip(fits, result.agreeing))
    good = [f for f in marked if f.accepted]
    informative = [f for f in marked if f.has_data and math.isfinite(f.se_ns)]
    anchor = result.anchor_ns if good else anchor_ns
    offset = result.offset_ns
    skew = result.skew_ppm
    skew_se = result.skew_se_ppm
    if skew_ppm and good:
        # the windows were binned with skew_ppm about anchor_ns taken out: compose the two lines
        first = ClockCorrection(offset_ns=0, skew_ppm=skew_ppm, anchor_ns=anchor_ns)
        offset = result.offset_ns + first.apply_one(anchor) - anchor
        skew = skew_ppm + result.skew_ppm
        if not math.isfinite(skew_se):  # no residual skew: the total is the first pass's, as uncertain
            skew_se = skew_se_ppm
    span = ((good[0].ref_start_ns, good[-1].ref_start_ns + good[-1].length_ns) if good else
            (marked[0].ref_start_ns, marked[-1].ref_start_ns + marked[-1].length_ns) if marked else (0, 0))
    peaks = [f.peak for f in (good or informative) if math.isfinite(f.peak)]
    return CameraFit(topic=topic, offset_ns=int(offset), skew_ppm=float(skew) if good else 0.0,
                     anchor_ns=int(anchor) if good else 0, accepted=result.accepted,
                     cost=1 - float(np.mean(peaks)) if peaks else math.inf,
                     confidence=len(good) / len(informative) if informative else 0.0, window_ns=span,
                     uncertainty_ns=result.se_ns if result.accepted else None,
                     skew_uncertainty_ppm=skew_se if result.accepted and math.isfinite(skew_se) else None,
                     reason=result.reason, kind=result.kind, windows_agreeing=len(good), windows_total=len(marked),
                     windows=marked,
                     spread_ns=result.spread_ns if result.accepted else None,
                     stretch_ns=span if result.quiet_outside else None, step=result.step)


def deskew_of(fit: CameraFit) -> ClockCorrection | None:
    """The skew-only correction a second pass should bin a camera's times with: its accepted line's
    skew about its anchor (None: no skew, the estimate is final)."""
    if not fit.skew_ppm or fit.windows_agreeing < 3:
        return None
    return ClockCorrection(offset_ns=0, skew_ppm=fit.skew_ppm, anchor_ns=fit.anchor_ns)
