"""How close one correlation over a whole real recording comes to the truth, against the refined
estimator's windows, where one camera's events are jittered: what the data hold, and what the
windows leave of it.

    ./dev run python studies/whole_recording.py [--seeds 200 206]

Virtual rigs cut from the real EVK4 recording (``evsync_testing.virtual``, as
``bench/realrigs.py``'s ``resampled`` group cuts them, seeds 200-209 by default there). For each
seed and variant: the refined estimate's error (``fit_camera``, judged at the middle of the
camera's recording), and the errors of one correlation of 100 us counts over the whole
recording, the camera's counts smoothed by a Gaussian of ``sigma`` (as the refinement smooths
them), its peak sought within 2 ms of a start offset and placed by a parabola. Two such
correlations, both yardsticks told where to look, not estimators:

* ``edge-safe``: the Pearson correlation of the reference's counts over the span both cameras
  recorded, less the reach (lags and kernel) at either end, with the camera's counts read beyond
  it, so every lag pairs the same reference bins with recorded camera bins (as the refinement
  pairs them). Started at the truth and 0.25 ms from it.
* ``zero-padded``: both cameras' counts over the union of their recordings, mean removed, zero
  padded, correlated by FFT (what this study used before 2026-11-26). The virtual cameras start
  and stop at the same instant, so their recordings' edges, steps from nothing to full activity,
  line up at the true offset, and this correlation reads them: cut the camera's first and last
  50 ms (the last column) and it falls to the edge of its search. Real cameras do not start
  together; the refinement drops such edges (``refined._recorded_spans``).

A refined ``se`` of nan: not accepted (its reason aside, the error is of its best guess).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from evsync_ros.core.engine.arrays import fit_camera
from evsync_ros.core.refined import RefinedParams
from evsync_ros.sim import simbag
from evsync_testing.realdata import read_events, real_data_dir
from evsync_testing.virtual import Case, virtual_rig

MS = 1_000_000
BIN_NS = 100_000
REACH = 2 * MS // BIN_NS
"""Lags either side of the start, in bins."""
VARIANTS: dict[str, dict[str, Any]] = {
    'parity, 1 ms jitter': {'split': 'parity', 'jitter_ns': 1_000_000},
    'random, 1 ms jitter': {'split': 'random', 'jitter_ns': 1_000_000},
    'parity, keep 0.1, noise 1.0, 0.5 ms jitter, late 0.4 s': {'split': 'parity', 'keep': 0.1, 'noise': 1.0,
                                                              'jitter_ns': 500_000, 'late_ns': 400 * MS},
}
COLUMNS: tuple[tuple[str, str, int, int, int], ...] = (
    # (label, kind, sigma, start, camera's ends cut)
    ('safe 0.5 from 0', 'safe', 500_000, 0, 0),
    ('safe 1.5 from 0', 'safe', 1_500_000, 0, 0),
    ('safe 1.5 from .25', 'safe', 1_500_000, 250_000, 0),
    ('zpad 1.5 from 0', 'zero-padded', 1_500_000, 0, 0),
    ('zpad 1.5, cut 50', 'zero-padded', 1_500_000, 0, 50 * MS),
)


def _kernel(sigma_ns: int) -> np.ndarray:
    half = int(3 * sigma_ns / BIN_NS)
    x = np.arange(-half, half + 1) * BIN_NS
    k = np.exp(-0.5 * (x / sigma_ns) ** 2)
    return k / k.sum()


def _vertex(c: np.ndarray, m: int) -> float:
    """The parabola's peak through c[m - 1], c[m], c[m + 1], as a fraction of a lag (0 at an end)."""
    if 0 < m < c.size - 1 and c[m - 1] - 2 * c[m] + c[m + 1] < 0:
        return float(0.5 * (c[m - 1] - c[m + 1]) / (c[m - 1] - 2 * c[m] + c[m + 1]))
    return 0.0


def edge_safe_error(ref: np.ndarray, cam_on_ref: np.ndarray, *, sigma_ns: int, start_ns: int) -> float:
    """The error in ns of the offset where the Pearson correlation of the reference's counts (over
    the span both recorded, less the reach either end) with the camera's smoothed counts, the
    camera on the reference's timeline and shifted by ``start_ns``, peaks."""
    cam = cam_on_ref + start_ns
    kernel = _kernel(sigma_ns)
    pad = kernel.size // 2
    margin = (REACH + pad + 1) * BIN_NS
    lo = max(int(ref[0]), int(cam[0])) + margin
    n = (min(int(ref[-1]), int(cam[-1])) - margin - lo) // BIN_NS
    inside = ref[(ref >= lo) & (ref < lo + n * BIN_NS)]
    a = np.bincount((inside - lo) // BIN_NS, minlength=n).astype(float)
    first = lo - (REACH + pad) * BIN_NS
    size = n + 2 * (REACH + pad)
    near = cam[(cam >= first) & (cam < first + size * BIN_NS)]
    b = np.convolve(np.bincount((near - first) // BIN_NS, minlength=size).astype(float), kernel, mode='valid')
    a -= a.mean()
    scores = np.empty(2 * REACH + 1)
    for k in range(scores.size):  # b[i + k] pairs a[i]: the camera read k - REACH bins later
        seg = b[k:k + n] - b[k:k + n].mean()
        scores[k] = float(a @ seg) / float(np.sqrt((a @ a) * (seg @ seg)))
    m = int(np.argmax(scores))
    # the shifted camera's events sit (m - REACH) bins late: the estimate moves them back by that
    return (REACH - m - _vertex(scores, m)) * BIN_NS + start_ns


def zero_padded_error(ref: np.ndarray, cam_on_ref: np.ndarray, *, sigma_ns: int, start_ns: int) -> float:
    """As ``edge_safe_error``, by the zero-padded correlation of both cameras' counts over the union of
    their recordings (which reads the recordings' edges)."""
    cam = cam_on_ref + start_ns
    t0 = min(int(ref[0]), int(cam[0]))
    n = (max(int(ref[-1]), int(cam[-1])) - t0) // BIN_NS + 1
    a = np.bincount((ref - t0) // BIN_NS, minlength=n).astype(float)
    b = np.convolve(np.bincount((cam - t0) // BIN_NS, minlength=n).astype(float), _kernel(sigma_ns), mode='same')
    a -= a.mean()
    b -= b.mean()
    corr = np.fft.irfft(np.fft.rfft(a, 2 * n) * np.conj(np.fft.rfft(b, 2 * n)), 2 * n)
    lags = np.arange(-REACH, REACH + 1)
    c = corr[lags % (2 * n)]
    m = int(np.argmax(c))
    # a[t + lag] pairs b[t]: the camera's events sit lag bins early; the estimate moves them by it
    return (lags[m] + _vertex(c, m)) * BIN_NS + start_ns


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seeds', type=int, nargs=2, default=(200, 206), metavar=('FIRST', 'END'))
    args = ap.parse_args()
    (events,) = read_events(real_data_dir() / 'evk4_hd').values()
    head = ' '.join(f'{label:>17}' for label, *_ in COLUMNS)
    for label, variant in VARIANTS.items():
        print(f'\n{label}: error ms (refined estimate | one correlation over the whole recording: kind, smoothing'
              f' ms, start ms, camera ends cut ms)')
        print(f'{"seed":>4} {"refined":>9} {"se":>6} | {head}')
        rows = []
        for seed in range(*args.seeds):
            case = Case('study', label, 'evk4_hd', offset_ns=37 * MS + 412_345, seed=seed, **variant)
            times, truth = virtual_rig(case, events)
            ref, cam = times['/a'], times['/b']
            fit = fit_camera(ref, cam, topic='/b', params=RefinedParams())
            err = simbag.error_ns(fit.as_json(), truth, int(np.median(cam)))
            on_ref = np.sort(cam + truth['offset_ns'])  # no skew in these variants
            whole = []
            for _, kind, sigma, start, cut in COLUMNS:
                c = on_ref[(on_ref >= on_ref[0] + cut) & (on_ref <= on_ref[-1] - cut)]
                error = edge_safe_error if kind == 'safe' else zero_padded_error
                whole.append(error(ref, c, sigma_ns=sigma, start_ns=start))
            rows.append([err, *whole])
            se = fit.uncertainty_ns / MS if fit.uncertainty_ns else float('nan')
            print(f'{seed:>4} {err / MS:>+9.3f} {se:>6.3f} | ' + ' '.join(f'{w / MS:>+17.3f}' for w in whole))
        errors = np.abs(np.array(rows)) / MS
        for name, value in (('rms', np.sqrt((errors ** 2).mean(axis=0))), ('max', errors.max(axis=0))):
            print(f'{name:>4} {value[0]:>9.3f} {"":>6} | ' + ' '.join(f'{v:>17.3f}' for v in value[1:]))


if __name__ == '__main__':
    main()
