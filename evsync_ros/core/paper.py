"""The paper's estimator, kept faithful: event-density alignment by brute-force search (Li, Dong, Qiu,
Han, Sec. 3.2): one window's search and the loop's outcome; the engine runs the loop (which windows,
until one is accepted) for every front end. numpy only; times are int64 nanoseconds. How this reads
the paper, and the one guard of ours: docs/method.md, "The paper's method"."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from evsync_ros.core.density import FloatArray, TimeArray, bin_counts, check_positive_int, paired_offset_ns
from evsync_ros.core.errors import ParameterError
from evsync_ros.core.results import CameraFit, Reason


@dataclass(frozen=True)
class PaperParams:
    """Parameters of the paper's method, with the paper's defaults."""

    tau_ns: int = 1_000_000
    """Bin width tau (1 ms)."""
    window_ns: int = 10_000_000_000
    """Window length T (10 s); a whole number of bins."""
    epsilon: float = 1e-4
    """Acceptance threshold on min D."""
    percentile: float = 50.0
    """Percentile p for the search range (the paper's 'binary percentile')."""
    min_overlap: float = 0.5
    """Least fraction of the window a candidate shift must overlap (0: any overlap, literally)."""

    def __post_init__(self) -> None:
        check_positive_int(self.tau_ns, name='tau_ns')
        check_positive_int(self.window_ns, name='window_ns')
        if self.window_ns % self.tau_ns:
            raise ParameterError(
                f'window_ns ({self.window_ns}) must be a whole number of bins of tau_ns ({self.tau_ns})'
            )
        if not (isinstance(self.epsilon, (int, float)) and math.isfinite(self.epsilon) and self.epsilon > 0):
            raise ParameterError(f'epsilon must be a finite positive number, got {self.epsilon!r}')
        if not (isinstance(self.percentile, (int, float)) and 0 < self.percentile < 100):
            raise ParameterError(f'percentile must be in (0, 100), got {self.percentile!r}')
        if not (isinstance(self.min_overlap, (int, float)) and 0 <= self.min_overlap < 1):
            raise ParameterError(f'min_overlap must be in [0, 1), got {self.min_overlap!r}')

    @property
    def max_shift_bins(self) -> int:
        """Largest |shift| that keeps min_overlap of the window (and at least one bin) overlapping."""
        n = self.n_bins
        return min(n - 1, n - math.ceil(self.min_overlap * n))

    @property
    def n_bins(self) -> int:
        """Bins per window, T / tau."""
        return self.window_ns // self.tau_ns


@dataclass(frozen=True)
class WindowResult:
    """The search in one pair of windows."""

    index: int
    """Window number k (0 is the first T seconds)."""
    ref_start_ns: int
    """Start of the reference window, reference timeline."""
    cam_start_ns: int
    """Start of the camera window, camera timeline."""
    search_range_bins: tuple[int, int]
    """[a, b] as searched (inclusive), before dropping shifts with no overlap."""
    shift_bins: int
    """dt* in bins (M_ref(t) ~ M_cam(t - dt*)); 0 if the window could not be searched."""
    cost: float
    """min D; +inf when a window held no events of one camera."""
    accepted: bool
    """cost < epsilon."""
    offset_ns: int
    """Offset implied by this window (package sign convention)."""
    ref_events: int
    cam_events: int


@dataclass(frozen=True)
class PaperEstimate:
    """The outcome for one camera against the reference."""

    offset_ns: int
    """Offset to add to the camera's times (from the accepted window, else the lowest-cost one)."""
    accepted: bool
    """Whether any window reached min D < epsilon."""
    cost: float
    window: WindowResult
    """The window the offset comes from."""
    windows: tuple[WindowResult, ...]
    """Every window tried, in order."""

    @classmethod
    def of(cls, windows: Sequence[WindowResult]) -> PaperEstimate:
        """The loop's outcome from the windows it tried (at least one): the accepted one, which ends
        the loop, else the lowest-cost one."""
        chosen = windows[-1] if windows[-1].accepted else min(windows, key=lambda w: w.cost)
        return cls(chosen.offset_ns, chosen.accepted, chosen.cost, chosen, tuple(windows))

    def as_camera(self, topic: str, *, params: PaperParams) -> CameraFit:
        """The outcome as a camera's decision in the contract's form: the paper has no confidence, so
        how far min D is below epsilon stands in for it."""
        w, cost = self.window, self.cost
        confidence = max(0.0, 1.0 - cost / params.epsilon) if math.isfinite(cost) else 0.0
        return CameraFit(topic=topic, offset_ns=self.offset_ns, skew_ppm=0.0, anchor_ns=0, accepted=self.accepted,
                         cost=cost if math.isfinite(cost) else 1e300, confidence=confidence,
                         window_ns=(w.ref_start_ns, w.ref_start_ns + params.window_ns),
                         reason='' if self.accepted else PAPER_REFUSED,
                         kind=Reason.NONE if self.accepted else Reason.EPSILON)


PAPER_REFUSED = Reason.EPSILON.value
"""Why the paper's loop accepts no window of a camera."""


def percentile_bin(density: FloatArray, percentile: float) -> int:
    """First bin where the cumulative density reaches ``percentile`` / 100."""
    cum = np.cumsum(density)
    idx = int(np.searchsorted(cum, percentile / 100.0 * cum[-1], side='left'))
    return min(idx, density.size - 1)


def search_range(m_ref: FloatArray, m_cam: FloatArray, *, percentile: float) -> tuple[int, int]:
    """[a, b] in bins: centre c = Q_ref - Q_cam, half-width 2|c| (see the module notes)."""
    c = percentile_bin(m_ref, percentile) - percentile_bin(m_cam, percentile)
    return c - 2 * abs(c), c + 2 * abs(c)


def dissimilarity(m_ref: FloatArray, m_cam: FloatArray, shift: int) -> float:
    """D of eq. (4): sum over the overlap of (M_ref(t) - M_cam(t - shift))^2; NaN if no overlap."""
    n_ref, n_cam = m_ref.size, m_cam.size
    lo = max(0, shift)
    hi = min(n_ref, n_cam + shift)
    if hi <= lo:
        return math.nan
    diff = m_ref[lo:hi] - m_cam[lo - shift : hi - shift]
    return float(np.dot(diff, diff))


def dissimilarity_curve(m_ref: FloatArray, m_cam: FloatArray, shifts: np.ndarray) -> FloatArray:
    """D for each shift, by direct traversal as in the paper (Fig. 4)."""
    return np.array([dissimilarity(m_ref, m_cam, int(s)) for s in shifts], dtype=np.float64)


def _argmin_near_centre(costs: FloatArray, shifts: np.ndarray, centre: float) -> int:
    best = np.nanmin(costs)
    ties = np.flatnonzero(costs == best)
    return int(ties[np.lexsort((shifts[ties], np.abs(shifts[ties] - centre)))[0]])


def estimate_window(
    ref_times: TimeArray,
    cam_times: TimeArray,
    *,
    ref_start_ns: int,
    cam_start_ns: int,
    index: int,
    params: PaperParams,
) -> WindowResult:
    """Search one pair of windows (see the module notes)."""
    n = params.n_bins
    c_ref = bin_counts(ref_times, start_ns=ref_start_ns, bin_ns=params.tau_ns, n_bins=n)
    c_cam = bin_counts(cam_times, start_ns=cam_start_ns, bin_ns=params.tau_ns, n_bins=n)
    return estimate_window_counts(c_ref, c_cam, ref_start_ns=ref_start_ns, cam_start_ns=cam_start_ns,
                                  index=index, params=params)


def estimate_window_counts(c_ref: np.ndarray, c_cam: np.ndarray, *, ref_start_ns: int, cam_start_ns: int,
                           index: int, params: PaperParams) -> WindowResult:
    """``estimate_window`` from the two windows' events per bin (what a stream keeps)."""
    n_ref, n_cam = int(c_ref.sum()), int(c_cam.sum())
    m_ref = c_ref / float(n_ref) if n_ref else np.zeros(c_ref.size)
    m_cam = c_cam / float(n_cam) if n_cam else np.zeros(c_cam.size)
    base = paired_offset_ns(ref_start_ns=ref_start_ns, cam_start_ns=cam_start_ns, bins_apart=0, bin_ns=params.tau_ns)
    if n_ref == 0 or n_cam == 0:
        return WindowResult(index, ref_start_ns, cam_start_ns, (0, 0), 0, math.inf, False, base, n_ref, n_cam)
    a, b = search_range(m_ref, m_cam, percentile=params.percentile)
    limit = params.max_shift_bins
    shifts = np.arange(max(a, -limit), min(b, limit) + 1, dtype=np.int64)
    if shifts.size == 0:  # the whole range lies beyond the overlap limit
        return WindowResult(index, ref_start_ns, cam_start_ns, (a, b), 0, math.inf, False, base, n_ref, n_cam)
    costs = dissimilarity_curve(m_ref, m_cam, shifts)
    k = _argmin_near_centre(costs, shifts, (a + b) / 2)
    shift, cost = int(shifts[k]), float(costs[k])
    return WindowResult(
        index=index,
        ref_start_ns=ref_start_ns,
        cam_start_ns=cam_start_ns,
        search_range_bins=(a, b),
        shift_bins=shift,
        cost=cost,
        accepted=cost < params.epsilon,
        offset_ns=paired_offset_ns(ref_start_ns=ref_start_ns, cam_start_ns=cam_start_ns, bins_apart=shift,
                                   bin_ns=params.tau_ns),
        ref_events=n_ref,
        cam_events=n_cam,
    )
