"""The estimator beyond the paper: normalised full-range search, sub-bin refinement, confidence, clock
drift and N cameras. numpy only; times are int64 ns on each camera's own timeline. How it works:
docs/method.md, "The refined method"."""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np

from evsync_ros.core.bins import BinnedStream, GridCounts, SortedTimes
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.density import FloatArray, TimeArray, as_times, check_positive_int
from evsync_ros.core.errors import ParameterError, StreamError
from evsync_ros.core.results import CameraFit, RigFit, WindowFit

SKEW_SIGNIFICANCE = 3.0
"""A fitted skew is reported only when it is this many standard errors from zero."""
MIN_DRIFT_WINDOWS = 5
"""Fewer accepted windows than this give no skew (the slope's error estimate needs the residuals)."""
TUKEY_C = 4.685
"""Tukey's biweight constant, in robust standard deviations (1.4826 x the median absolute residual):
95 % efficiency on Gaussian residuals, and windows beyond it have no weight in the drift line."""
ROBUST_ITERATIONS = 10


@dataclass(frozen=True)
class RefinedParams:
    """Parameters of the refined estimator."""

    tau_ns: int = 1_000_000
    """Coarse bin width (1 ms, as the paper)."""
    window_ns: int = 10_000_000_000
    """Window length T (10 s, as the paper)."""
    hop_ns: int = 5_000_000_000
    """Windows start this far apart (overlapping by half with the defaults)."""
    max_shift_ns: int = 5_000_000_000
    """Search half-range S around the prior offset."""
    min_overlap: float = 0.5
    """Least fraction of the window a candidate lag must overlap."""
    fine_ns: int = 100_000
    """Fine bin width of the refinement (100 us). The camera's counts are smoothed by 500 us or more,
    so finer bins add cost, not precision: with 50 us bins (`studies/smoothing.py --fine-us 50`) the
    drift preset's windows err alike (20.3 against 20.2 us rms), with twice the bins to count,
    smooth and correlate."""
    smooth_ns: int | tuple[int, ...] = (500_000, 1_000_000, 2_000_000)
    """Gaussian sigmas, one of which smooths the camera's fine counts in each window (an int is one
    sigma): the one whose smoothed counts correlate best with the reference's at their peak, i.e.
    the one that best predicts the reference from the camera. How far the envelopes agree differs
    by scene. On the per-pixel simulator (agreeing up to about 50-100 Hz) `studies/smoothing.py`
    scatters drift windows by 48.8 us rms with a fixed 500 us, 27.0 with 1 ms, 19.3 with 2 ms, 18.3
    with 3 ms, and 20.2 with this choice, which takes 1-2 ms there (adding 3 or 4 ms to it changes
    nothing: they never correlate best). On envelopes with sharp common edges (the tests' synthetic
    streams) it takes 500 us, where a fixed 2 ms errs by up to 60 us."""
    lobe_margin_ns: int = 20_000_000
    """Rival peaks are sought outside the main lobe widened by this much."""
    min_confidence: float = 0.2
    """A window is accepted when its confidence reaches this."""
    drift: bool = True
    """Fit a skew from several accepted windows (else the first accepted window's offset only)."""

    def __post_init__(self) -> None:
        for name in ('tau_ns', 'window_ns', 'hop_ns', 'max_shift_ns', 'fine_ns', 'lobe_margin_ns'):
            check_positive_int(getattr(self, name), name=name)
        sigmas = self._smooth_tuple
        if not sigmas:
            raise ParameterError('smooth_ns must be a sigma or a tuple of sigmas (ns), got ()')
        for sigma in sigmas:
            check_positive_int(sigma, name='smooth_ns')
        if self.window_ns % self.tau_ns or self.tau_ns % self.fine_ns:
            raise ParameterError('window_ns must be a whole number of tau_ns, and tau_ns of fine_ns')
        if not (isinstance(self.min_overlap, (int, float)) and 0 < self.min_overlap <= 1):
            raise ParameterError(f'min_overlap must be in (0, 1], got {self.min_overlap!r}')
        if not (isinstance(self.min_confidence, (int, float)) and 0 <= self.min_confidence <= 1):
            raise ParameterError(f'min_confidence must be in [0, 1], got {self.min_confidence!r}')

    @property
    def refine_reach_ns(self) -> int:
        """How far beyond a window, either side of its coarse offset, the refinement reads the camera."""
        return 2 * self.tau_ns + _half_width(max(self.sigmas_ns) / self.fine_ns) * self.fine_ns

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


# --- correlation ---------------------------------------------------------------------------------

def _xcorr(x: FloatArray, y: FloatArray, size: int, *, y_f: np.ndarray | None = None) -> FloatArray:
    """c[m] = sum_i x[i] * y[i + m] for m = 0 .. len(y) - 1 (x shorter than y), by FFT; ``y_f`` is
    ``np.fft.rfft(y, size)`` when the caller has it already."""
    fx = np.fft.rfft(x, size)
    fy = np.fft.rfft(y, size) if y_f is None else y_f
    return np.fft.irfft(np.conj(fx) * fy, size)[: y.size]


def ncc_all_lags(a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Pearson correlation of a[i] with b[i + m] over each lag's own overlap, for m = 0 .. len(b)-1.

    Returns (ncc, overlap): overlap[m] is how many samples of ``a`` lag m pairs. ``a`` must not be
    longer than ``b``. NaN where either side is constant over the overlap.

    Lag m pairs a[:k] with b[m:m + k], k = min(len(a), len(b) - m), so every sum but the cross
    term is a difference of prefix sums; the cross term is one correlation by FFT.
    """
    n = a.size
    m = np.arange(b.size)
    count = np.minimum(n, b.size - m)
    a_sums, aa_sums, b_sums, bb_sums = (np.concatenate([[0.0], np.cumsum(x)]) for x in (a, a * a, b, b * b))
    sa, saa = a_sums[count], aa_sums[count]
    sb, sbb = b_sums[m + count] - b_sums[m], bb_sums[m + count] - bb_sums[m]
    sab = _xcorr(a, b, 1 << int(math.ceil(math.log2(n + b.size))))
    count = count.astype(np.float64)
    with np.errstate(invalid='ignore', divide='ignore'):
        cov = sab - sa * sb / count
        va = saa - sa * sa / count
        vb = sbb - sb * sb / count
        ncc = cov / np.sqrt(va * vb)
        tiny = 1e-9 * max(float(np.dot(a, a)), 1e-300)
        ncc[(va <= tiny) | (vb <= 1e-9 * max(float(np.dot(b, b)), 1e-300)) | (count < 2)] = np.nan
    return ncc, count


Counts = SortedTimes | BinnedStream | GridCounts
"""Where the windows' counts come from: a sorted array held whole, or a stream's binned counts."""


def _source(x: TimeArray | Counts) -> Counts:
    return x if isinstance(x, (SortedTimes, BinnedStream, GridCounts)) else SortedTimes(x)


def _half_width(sigma_bins: float) -> int:
    return max(1, int(math.ceil(3 * sigma_bins)))


def _gaussian(sigma_bins: float) -> FloatArray:
    half = _half_width(sigma_bins)
    x = np.arange(-half, half + 1)
    k = np.exp(-0.5 * (x / sigma_bins) ** 2)
    return k / k.sum()


def _confidence(ncc: FloatArray, best: int, lobe_margin: int) -> tuple[float, float]:
    peak = float(ncc[best])
    if not peak > 0:
        return peak, 0.0
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
    return peak, max(0.0, min(1.0, peak * (1 - max(rival, 0.0) / peak)))


# --- one window ----------------------------------------------------------------------------------

def fit_window(ref: TimeArray | Counts, cam: TimeArray | Counts, *, ref_start_ns: int, prior_ns: int,
               params: RefinedParams) -> WindowFit:
    """Coarse NCC over every lag in [-S, S], refinement, confidence (module notes 1-3).

    ``cam`` holds the camera's times (or binned counts) already mapped onto the reference timeline
    by everything but the offset being sought (the skew correction, on the second pass);
    ``prior_ns`` is the offset the search is centred on. Binned streams need ``ref_start_ns`` and
    ``ref_start_ns - prior_ns`` on their grids.
    """
    p = params
    ref, cam = _source(ref), _source(cam)
    n = p.window_ns // p.tau_ns
    s = p.max_shift_ns // p.tau_ns
    a = ref.counts(ref_start_ns, p.tau_ns, n)
    # camera time c pairs with reference time c + offset; offset = prior + lag
    cam_start = ref_start_ns - prior_ns - s * p.tau_ns
    b = cam.counts(cam_start, p.tau_ns, n + 2 * s)
    ncc, count = ncc_all_lags(a, b)
    # b[i + m] pairs a[i]: camera time cam_start + (i + m) tau = reference time ref_start + i tau - offset
    # so offset = prior + (s - m) tau, lag = (s - m) tau
    lags = (s - np.arange(ncc.size)) * p.tau_ns
    ncc[count < p.min_overlap * n] = np.nan
    lags, ncc = lags[::-1].copy(), ncc[::-1].copy()  # increasing lag
    if a.sum() == 0 or b.sum() == 0 or np.all(np.isnan(ncc)):
        return WindowFit(ref_start_ns=ref_start_ns, offset_ns=prior_ns, peak=math.nan, confidence=0.0, accepted=False,
                         lags_ns=lags, ncc=ncc, prior_ns=prior_ns, ref_counts=a, cam_counts=b)
    best = int(np.nanargmax(ncc))
    peak, confidence = _confidence(ncc, best, p.lobe_margin_ns // p.tau_ns)
    coarse = prior_ns + int(lags[best])
    offset = _refine(ref, cam, ref_start_ns=ref_start_ns, coarse_ns=coarse, params=p)
    return WindowFit(ref_start_ns=ref_start_ns, offset_ns=offset, peak=peak, confidence=confidence,
                     accepted=confidence >= p.min_confidence, lags_ns=lags, ncc=ncc, prior_ns=prior_ns, ref_counts=a,
                     cam_counts=b)


def _refine(ref: Counts, cam: Counts, *, ref_start_ns: int, coarse_ns: int, params: RefinedParams) -> int:
    p = params
    f = p.fine_ns
    n = p.window_ns // f
    reach = 2 * (p.tau_ns // f)  # fine lags within two coarse bins of the coarse peak
    pad = _half_width(p.sigmas_ns[-1] / f)  # the widest kernel's half: every smoothing sees real counts
    a = ref.counts(ref_start_ns, f, n)
    a -= a.mean()
    va = float(np.dot(a, a))
    raw = cam.counts(ref_start_ns - coarse_ns - (reach + pad) * f, f, n + 2 * (reach + pad))
    # b = the smoothed counts from pad on; b[i + m] pairs a[i] at offset coarse + (reach - m) f. With a
    # zero-mean, the covariance at lag m is sum_i a[i] b[i + m], the raw counts' covariance (one FFT
    # for every lag and every smoothing) smoothed by the kernel; b's variance over each slice comes
    # from its sums, moved along the slice's two ends. Each smoothing of the raw counts is one inverse
    # FFT of their transform, which the covariance needs anyway (a direct convolution of 10^5 bins
    # costs about twice that).
    size = 1 << int(math.ceil(math.log2(raw.size)))
    raw_f = np.fft.rfft(raw, size)
    raw_cov = _xcorr(a, raw, size, y_f=raw_f)
    best = (-math.inf, coarse_ns)
    for sigma in p.sigmas_ns:
        kernel = _gaussian(sigma / f)
        h = (kernel.size - 1) // 2
        cov = np.convolve(raw_cov[pad - h:pad + h + 2 * reach + 1], kernel, mode='valid')
        b = np.fft.irfft(raw_f * _gaussian_spectrum(sigma / f, size), size)[pad:pad + n + 2 * reach]
        sb = _slice_sums(b, n)
        vb = _slice_sums(b * b, n) - sb * sb / n
        peak, offset = _fine_peak(cov, va, vb, coarse_ns=coarse_ns, reach=reach, fine_ns=f)
        if peak > best[0]:
            best = (peak, offset)
    return best[1]


@functools.lru_cache(maxsize=8)
def _gaussian_spectrum(sigma_bins: float, size: int) -> np.ndarray:
    """The real FFT of ``_gaussian(sigma_bins)`` centred on sample 0 of a circle of ``size``: what
    multiplies a transform of that size to smooth it as ``np.convolve(x, kernel, 'same')`` does,
    away from the ends (read-only: it is shared)."""
    kernel = _gaussian(sigma_bins)
    h = (kernel.size - 1) // 2
    circle = np.zeros(size)
    circle[:h + 1] = kernel[h:]
    circle[size - h:] = kernel[:h]
    spectrum = np.fft.rfft(circle)
    spectrum.flags.writeable = False
    return spectrum


def _slice_sums(x: FloatArray, n: int) -> FloatArray:
    """sum(x[m:m + n]) for m = 0 .. len(x) - n."""
    ends = x[n:] - x[:x.size - n]
    return float(x[:n].sum()) + np.concatenate([[0.0], np.cumsum(ends)])


def _fine_peak(cov: FloatArray, va: float, vb: FloatArray, *, coarse_ns: int, reach: int, fine_ns: int
               ) -> tuple[float, int]:
    """(NCC at the peak, offset) from the covariance and the camera's variance at lags m = 0 .. 2 reach
    (offset coarse + (reach - m) fine); -inf when either side is flat."""
    with np.errstate(invalid='ignore', divide='ignore'):
        scores = np.where((vb > 0) & (va > 0), cov / np.sqrt(va * np.maximum(vb, 1e-300)), np.nan)
    if np.all(np.isnan(scores)):
        return -math.inf, coarse_ns
    m = int(np.nanargmax(scores))
    frac = 0.0
    if 0 < m < scores.size - 1 and not np.isnan(scores[m - 1]) and not np.isnan(scores[m + 1]):
        y0, y1, y2 = scores[m - 1], scores[m], scores[m + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            frac = 0.5 * (y0 - y2) / den
    return float(scores[m]), int(round(coarse_ns + (reach - m - frac) * fine_ns))


# --- one camera ----------------------------------------------------------------------------------

def first_window_reaching(rel_ns: Any, params: RefinedParams) -> Any:
    """The first window (starting every hop from 0) whose end is after ``rel_ns`` (an int or an array)."""
    return -((params.window_ns - 1 - rel_ns) // params.hop_ns)


def _window_starts(ref: TimeArray, params: RefinedParams) -> list[int]:
    """Windows every hop from the first event to the last whole one, those with a reference event in
    them (a gap, a clock jump, a corrupt time is stepped over, not walked window by window)."""
    first, last = int(ref[0]), int(ref[-1])
    span = last - first + 1
    if span <= params.window_ns:
        return [first]
    count = (span - params.window_ns) // params.hop_ns + 1
    rel = ref - np.int64(first)
    hi = np.minimum(rel // params.hop_ns, count - 1)
    pairs = np.stack([np.maximum(first_window_reaching(rel, params), 0), hi])
    if np.all(rel[1:] >= rel[:-1]):
        # sorted times: each event's range of windows follows the last one's, so the distinct ranges
        # are where either end changes (np.unique would sort a million pairs for the same answer)
        pairs = pairs[:, np.concatenate([[0], np.flatnonzero(np.any(pairs[:, 1:] != pairs[:, :-1], axis=0)) + 1])]
    else:
        pairs = np.unique(pairs, axis=1)
    ks: list[int] = []
    for a, b in zip(*pairs.tolist()):
        a = max(a, ks[-1] + 1 if ks else 0)
        ks.extend(range(a, b + 1))
    return [first + k * params.hop_ns for k in ks]


class LineWindow(Protocol):
    """What the drift line reads of a window: where it starts, its offset, its weight."""

    @property
    def ref_start_ns(self) -> int: ...

    @property
    def offset_ns(self) -> int: ...

    @property
    def confidence(self) -> float: ...


def fit_line(fits: Sequence[LineWindow], params: RefinedParams, *, min_windows: int = MIN_DRIFT_WINDOWS
              ) -> tuple[int, float, int, float]:
    """(offset at anchor, slope ppm, anchor, slope standard error ppm) through the accepted windows.

    Window centres are on the camera's timeline; weights are the windows' confidences. With fewer
    than ``min_windows`` windows (at least 3: the error needs a residual), the offsets are averaged
    (slope 0, error inf). From ``MIN_DRIFT_WINDOWS`` windows on, the line is robust: Tukey's
    biweight on the residuals (``TUKEY_C`` robust standard deviations, refitted
    ``ROBUST_ITERATIONS`` times) takes out a window whose offset the scene pulled away from the
    others, which a least-squares slope over a minute would follow by ppm.
    """
    half = params.window_ns // 2
    w0 = np.array([f.confidence for f in fits])
    x = np.array([f.ref_start_ns + half - f.offset_ns for f in fits], dtype=np.float64)
    y = np.array([f.offset_ns for f in fits], dtype=np.float64)
    anchor = int(round(float(np.average(x, weights=w0))))
    if len(fits) < max(3, min_windows) or not params.drift:
        return int(round(float(np.average(y, weights=w0)))), 0.0, anchor, math.inf
    dx = x - anchor

    def weighted(w: np.ndarray) -> tuple[float, float, np.ndarray, float]:
        """(offset at the anchor, slope, residuals, weighted spread of the centres)"""
        xm = float(np.average(dx, weights=w))
        ym = float(np.average(y, weights=w))
        sxx = float(np.sum(w * (dx - xm) ** 2))
        slope = float(np.sum(w * (dx - xm) * (y - ym))) / sxx
        y0 = ym - slope * xm
        return y0, slope, y - y0 - slope * dx, sxx

    w = w0
    y0, slope, resid, sxx = weighted(w)
    for _ in range(ROBUST_ITERATIONS if len(fits) >= MIN_DRIFT_WINDOWS else 0):
        scale = 1.4826 * float(np.median(np.abs(resid)))
        if scale <= 0:
            break
        u = resid / (TUKEY_C * scale)
        tukey = w0 * np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
        if np.count_nonzero(tukey) < MIN_DRIFT_WINDOWS:
            break
        w = tukey
        y0, slope, resid, sxx = weighted(w)
    dof = np.count_nonzero(w) - 2
    se = math.sqrt(float(np.sum(w * resid * resid)) / dof / sxx)
    return int(round(y0)), slope * 1e6, anchor, se * 1e6


def first_pass(topic: str, fits: Sequence[WindowFit], params: RefinedParams
               ) -> tuple[CameraFit, ClockCorrection | None]:
    """A camera's estimate from its windows, and the skew correction a second pass should bin its
    times with (None when there is no significant skew: the estimate is final)."""
    good = [f for f in fits if f.accepted]
    if not good:
        best = max(fits, key=lambda f: (f.confidence, -math.inf if math.isnan(f.peak) else f.peak))
        return CameraFit(topic=topic, offset_ns=best.offset_ns, skew_ppm=0.0, anchor_ns=0, accepted=False,
                         cost=1 - best.peak if not math.isnan(best.peak) else math.inf, confidence=best.confidence,
                         window_ns=(best.ref_start_ns, best.ref_start_ns + params.window_ns), windows=tuple(fits)), None
    offset, skew, anchor, se = fit_line(good, params)
    if not params.drift or len(good) < MIN_DRIFT_WINDOWS or abs(skew) < SKEW_SIGNIFICANCE * se:
        # no drift asked for, too few windows, or a slope within its noise: offsets averaged
        return _accepted(topic, offset, 0.0, anchor, fits, params), None
    return (_accepted(topic, offset, skew, anchor, fits, params),
            ClockCorrection(offset_ns=0, skew_ppm=skew, anchor_ns=anchor))


def second_pass(first: CameraFit, fits: Sequence[WindowFit], params: RefinedParams) -> CameraFit:
    """The estimate from windows binned with ``first``'s skew taken out: the residual slope adds to it."""
    good = [f for f in fits if f.accepted]
    if len(good) < MIN_DRIFT_WINDOWS:
        return first
    offset, residual, _, _ = fit_line(good, params)
    return _accepted(first.topic, offset, first.skew_ppm + residual, first.anchor_ns, fits, params)


def _accepted(topic: str, offset: int, skew: float, anchor: int, fits: Sequence[WindowFit],
              params: RefinedParams) -> CameraFit:
    good = [f for f in fits if f.accepted]
    return CameraFit(topic=topic, offset_ns=offset, skew_ppm=skew, anchor_ns=anchor, accepted=True,
                     cost=1 - float(np.mean([f.peak for f in good])),
                     confidence=float(np.mean([f.confidence for f in good])),
                     window_ns=(good[0].ref_start_ns, good[-1].ref_start_ns + params.window_ns), windows=tuple(fits))


def fit_camera(ref: TimeArray, cam: TimeArray, *, topic: str, prior_ns: int | None = None,
               params: RefinedParams = RefinedParams()) -> CameraFit:
    """One camera against the reference (module notes 1-4); times must be sorted."""
    if prior_ns is None:
        prior_ns = int(ref[0]) - int(cam[0])  # cameras started about together
    starts = _window_starts(ref, params)
    fits = [fit_window(ref, cam, ref_start_ns=w, prior_ns=prior_ns, params=params) for w in starts]
    first, deskew = first_pass(topic, fits, params)
    if deskew is None:
        return first
    # second pass: camera times with the skew taken out, offsets sought near the line
    cam2 = SortedTimes(deskew.apply(cam))
    return second_pass(first, [fit_window(ref, cam2, ref_start_ns=w, prior_ns=first.offset_ns, params=params)
                               for w in starts], params)


# --- N cameras -----------------------------------------------------------------------------------

def estimate_rig(streams: Mapping[str, object], *, reference: str, params: RefinedParams = RefinedParams(),
                 consistency: bool = True, priors_ns: Mapping[str, int] | None = None) -> RigFit:
    """Every camera against ``reference``; with ``consistency``, every other pair too, as a check."""
    if reference not in streams:
        raise StreamError(f'reference stream {reference!r} is not among {sorted(streams)}')
    times = {}
    for name, t in streams.items():
        arr = as_times(t, name=name)
        if arr.size == 0:
            raise StreamError(f'stream {name!r}: no events to estimate from')
        times[name] = arr if np.all(arr[1:] >= arr[:-1]) else np.sort(arr)
    ref = times[reference]
    first = ref[0]
    fits = [CameraFit.reference_entry(reference, start_ns=int(first), window_ns=params.window_ns)]
    priors = dict(priors_ns or {})
    for name, cam in times.items():
        if name != reference:
            fits.append(fit_camera(ref, cam, topic=name, prior_ns=priors.get(name), params=params))
    residuals: dict[tuple[str, str], int] = {}
    if consistency:
        single = replace(params, drift=False)
        accepted = [f for f in fits[1:] if f.accepted]
        for i, fi in enumerate(accepted):
            for fj in accepted[i + 1:]:
                # j against i: camera j's times onto camera i's timeline
                ti = times[fi.topic]
                pair = fit_camera(fi.correction.apply(ti), fj.correction.apply(times[fj.topic]),
                                  topic=fj.topic, prior_ns=0, params=single)
                if pair.accepted:
                    residuals[(fi.topic, fj.topic)] = pair.offset_ns
    return RigFit(reference=reference, cameras=tuple(fits), pair_residual_ns=residuals)
