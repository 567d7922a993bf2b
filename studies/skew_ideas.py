"""Ideas for the drift line at 60 s, each measured against the line through the windows as they are.

    ./dev run python studies/skew_ideas.py [--seeds 10] [--highpass-ms 25 50 100]

Issue 7 asks for a skew within 1 ppm on recordings of 60 s; the refined estimator's worst of 20
drifting cameras was 2.05 ppm before the agreement rule (docs/studies.md, "Skew and the recording's
length"; 0.76 ppm since, docs/benchmarks.md). The drift preset's recordings are taken here in
*true* time, so every window's right offset is 0 and a line through a camera's windows is its skew
error. Every window but each camera's first is fitted alone (``refined.fit_window``, the default
parameters), and each idea turns those windows into a slope; the table gives the rms and the
largest over the cameras:

* line: a least-squares line through the windows (as ``studies/smoothing.py``);
* confidence weights: the same line weighted by each window's confidence (what an
  earlier estimator weighted by before its robust reweighting);
* sharpness weights: weighted by the coarse correlation peak's sharpness (its height over the mean
  of its two neighbours), a window with a narrow peak being the better placed;
* high-passed: both cameras' counts, coarse and fine, with their Gaussian-smoothed selves (sigma in
  ms) taken out before the fit, so that the slow part of the envelopes, whose delay differs most
  between bands (``studies/limits.py``), places no window;
* pair closure: the third pair (camera 2 against camera 1) fitted as well, and each camera's slope
  the least-squares solution of the triangle (s1, s2, s2 - s1);
* rate regressors: each window's offset regressed on the line and on the log of both cameras'
  event counts in the window, in case the wander follows how busy the scene is.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import sys
import time

import numpy as np

from evsync_ros.core.bins import SortedTimes
from evsync_ros.core.refined import RefinedParams, _gaussian, _half_width, fit_window, window_starts
from evsync_ros.sim import pixelsim

PARAMS = RefinedParams()


class HighPassed(SortedTimes):
    """A stream's counts with their Gaussian-smoothed selves taken out (and the mean kept, so that a
    window with events still counts some): what ``fit_window`` reads in place of the plain counts."""

    def __init__(self, times: np.ndarray, sigma_ns: int) -> None:
        super().__init__(times)
        self.sigma_ns = sigma_ns

    def counts(self, start_ns: int, bin_ns: int, n: int) -> np.ndarray:
        sigma = self.sigma_ns / bin_ns
        half = _half_width(sigma)
        x = super().counts(start_ns - half * bin_ns, bin_ns, n + 2 * half)
        slow = np.convolve(x, _gaussian(sigma), mode='same')
        inner = (x - slow)[half:half + n]
        return inner + float(x[half:half + n].mean())


def windows(ref, cam, ref_t: np.ndarray, cam_t: np.ndarray | None = None) -> np.ndarray:
    """Per window after the first: centre (s), offset (us), confidence, coarse sharpness, log events of
    both streams in the window (the last two only with ``cam_t``)."""
    starts, length = window_starts(ref_t, PARAMS)
    rows = []
    for w in starts[1:]:
        fit = fit_window(ref, cam, ref_start_ns=w, length_ns=length, prior_ns=0, params=PARAMS)
        best = int(np.nanargmax(fit.ncc))
        sharp = fit.ncc[best] - 0.5 * (fit.ncc[max(best - 1, 0)] + fit.ncc[min(best + 1, fit.ncc.size - 1)])
        counts = [0.0, 0.0]
        if cam_t is not None:
            counts = [math.log(max(1, int(np.searchsorted(t, w + length) - np.searchsorted(t, w))))
                      for t in (ref_t, cam_t)]
        rows.append(((w - starts[0] + length / 2) / 1e9, fit.offset_ns / 1e3, fit.confidence, sharp,
                     *counts))
    return np.array(rows)


def one(job: tuple[int, tuple[int, ...]]) -> dict:
    """One drift recording: each camera's windows against the reference, as is and high-passed, and
    the second camera's against the first."""
    seed, highpass_ns = job
    rig = pixelsim.preset('drift', seed=seed)
    events = pixelsim.simulate(rig)
    true = {c.topic: np.sort(np.rint(events[c.topic].true_t).astype(np.int64)) for c in rig.cameras}
    ref_t = true[rig.reference]
    cams = [c.topic for c in rig.cameras if c.topic != rig.reference]
    out: dict = {'plain': [windows(SortedTimes(ref_t), SortedTimes(true[c]), ref_t, true[c]) for c in cams]}
    for sigma in highpass_ns:
        out[sigma] = [windows(HighPassed(ref_t, sigma), HighPassed(true[c], sigma), ref_t) for c in cams]
    if len(cams) == 2:
        out['pair'] = windows(SortedTimes(true[cams[0]]), SortedTimes(true[cams[1]]), true[cams[0]])
    return out


def slope(rows: np.ndarray, weights: np.ndarray | None = None, extra: list[np.ndarray] | None = None) -> float:
    """The slope (ppm) of a (weighted) least-squares line through the windows, with optional regressors."""
    x = np.column_stack([np.ones(len(rows)), rows[:, 0], *(extra or [])])
    w = np.sqrt(weights) if weights is not None else np.ones(len(rows))
    return float(np.linalg.lstsq(x * w[:, None], rows[:, 1] * w, rcond=None)[0][1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--seeds', type=int, default=10)
    ap.add_argument('--jobs', type=int, default=2)
    ap.add_argument('--highpass-ms', type=int, nargs='*', default=[25, 50, 100])
    args = ap.parse_args()
    highpass = tuple(v * 1_000_000 for v in args.highpass_ms)
    t0 = time.perf_counter()
    with multiprocessing.Pool(args.jobs) as pool:
        parts = pool.map(one, [(s, highpass) for s in range(args.seeds)], chunksize=1)
    plain = [r for p in parts for r in p['plain']]
    rows: list[tuple[str, list[float]]] = [
        ('line', [slope(r) for r in plain]),
        ('confidence weights', [slope(r, r[:, 2]) for r in plain]),
        ('sharpness weights', [slope(r, np.maximum(r[:, 3], 1e-9)) for r in plain]),
    ]
    rows += [(f'high-passed {s // 1_000_000} ms', [slope(r) for p in parts for r in p[s]]) for s in highpass]
    closed = []
    for p in parts:
        if 'pair' in p:
            s1, s2, s12 = slope(p['plain'][0]), slope(p['plain'][1]), slope(p['pair'])
            closed += [(2 * s1 + s2 - s12) / 3, (s1 + 2 * s2 + s12) / 3]
    rows.append(('pair closure', closed))
    rows.append(('rate regressors', [slope(r, extra=[r[:, 4], r[:, 5]]) for r in plain]))
    print(f'drift: {args.seeds} recordings of 60 s, {len(plain)} cameras against the reference, true times, '
          f'in {time.perf_counter() - t0:.0f} s\n')
    head = f'{"idea":<22} {"cameras":>7} | {"slope rms ppm":>13} {"max":>6} {"<= 1 ppm":>9}'
    print(head)
    print('-' * len(head))
    for name, slopes in rows:
        s = np.abs(np.array(slopes))
        print(f'{name:<22} {s.size:7d} | {math.sqrt(float(np.mean(s ** 2))):13.2f} {float(s.max()):6.2f} '
              f'{int(np.sum(s <= 1.0)):>5d}/{s.size:<3d}')
    print('\nslope: the line through a camera\'s windows on true times, i.e. its skew error (ppm); every camera\'s '
          'first window left out. The estimator itself also reweights the windows robustly (Tukey) and fits a '
          'second pass; this table compares the ideas on the same windows.')
    return 0


if __name__ == '__main__':
    sys.exit(main())
