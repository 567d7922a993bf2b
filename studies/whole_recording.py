"""How close one correlation over a whole real recording comes to the truth, against the refined
estimator's windows, where one camera's events are jittered: what the data hold, and what the
windows leave of it.

    ./dev run python studies/whole_recording.py [--seeds 200 206]

Virtual rigs cut from the real EVK4 recording (``evsync_ros.testing.virtual``, as
``bench/realrigs.py``'s ``resampled`` group cuts them, seeds 200-209 by default there). For each
seed and variant: the refined estimate's error (``fit_camera``, judged at the middle of the
camera's recording), and the error of one mean-removed, zero-padded correlation of 100 us counts
over the whole recording, the camera's counts smoothed by a Gaussian of ``sigma`` (as the
refinement smooths them), its peak sought within 2 ms of a start offset (the truth, or 0.25 ms
either side of it, so the search's own pull towards where it starts shows) and placed by a parabola.
The whole-recording correlation is a yardstick, not an estimator: it is told where to look.
A refined ``se`` of nan: not accepted (its reason aside, the error is of its best guess).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from evsync_ros.core.refined import RefinedParams, fit_camera
from evsync_ros.sim import simbag
from evsync_ros.testing.realdata import read_events, real_data_dir
from evsync_ros.testing.virtual import Case, virtual_rig

MS = 1_000_000
BIN_NS = 100_000
VARIANTS: dict[str, dict[str, Any]] = {
    'parity, 1 ms jitter': {'split': 'parity', 'jitter_ns': 1_000_000},
    'random, 1 ms jitter': {'split': 'random', 'jitter_ns': 1_000_000},
    'parity, keep 0.1, noise 1.0, 0.5 ms jitter, late 0.4 s': {'split': 'parity', 'keep': 0.1, 'noise': 1.0,
                                                              'jitter_ns': 500_000, 'late_ns': 400 * MS},
}
SIGMAS_NS = (500_000, 1_500_000)
STARTS_NS = (0, 250_000, -250_000)


def whole_correlation_error(ref: np.ndarray, cam_on_ref: np.ndarray, *, sigma_ns: int, start_ns: int) -> float:
    """Where the correlation of ``ref`` with ``cam_on_ref`` (the camera on the reference's timeline,
    shifted by ``start_ns``) peaks, less the shift: the error in ns of an estimate so made."""
    cam = cam_on_ref + start_ns
    t0 = min(int(ref[0]), int(cam[0]))
    n = (max(int(ref[-1]), int(cam[-1])) - t0) // BIN_NS + 1
    a = np.bincount((ref - t0) // BIN_NS, minlength=n).astype(float)
    b = np.bincount((cam - t0) // BIN_NS, minlength=n).astype(float)
    half = int(3 * sigma_ns / BIN_NS)
    x = np.arange(-half, half + 1) * BIN_NS
    kernel = np.exp(-0.5 * (x / sigma_ns) ** 2)
    b = np.convolve(b, kernel / kernel.sum(), mode='same')
    a -= a.mean()
    b -= b.mean()
    corr = np.fft.irfft(np.fft.rfft(a, 2 * n) * np.conj(np.fft.rfft(b, 2 * n)), 2 * n)
    reach = 2 * MS // BIN_NS
    lags = np.arange(-reach, reach + 1)
    c = corr[lags % (2 * n)]
    m = int(np.argmax(c))
    frac = 0.0
    if 0 < m < c.size - 1 and c[m - 1] - 2 * c[m] + c[m + 1] < 0:
        frac = 0.5 * (c[m - 1] - c[m + 1]) / (c[m - 1] - 2 * c[m] + c[m + 1])
    # a[t + lag] pairs b[t]: the camera's events sit lag bins early; the estimate moves them by it
    return (lags[m] + frac) * BIN_NS + start_ns


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seeds', type=int, nargs=2, default=(200, 206), metavar=('FIRST', 'END'))
    args = ap.parse_args()
    (events,) = read_events(real_data_dir() / 'evk4_hd').values()
    head = ' '.join(f'{f"{s / MS:g} ms from {o / MS:+g}":>16}' for s in SIGMAS_NS for o in STARTS_NS)
    for label, variant in VARIANTS.items():
        print(f'\n{label}: error ms (refined estimate | one correlation over the whole recording, smoothing'
              f' from start)')
        print(f'{"seed":>4} {"refined":>9} {"se":>6} | {head}')
        worst = np.zeros(len(SIGMAS_NS) * len(STARTS_NS))
        for seed in range(*args.seeds):
            case = Case('study', label, 'evk4_hd', offset_ns=37 * MS + 412_345, seed=seed, **variant)
            times, truth = virtual_rig(case, events)
            ref, cam = times['/a'], times['/b']
            fit = fit_camera(ref, cam, topic='/b', params=RefinedParams())
            err = simbag.error_ns(fit.as_json(), truth, int(np.median(cam)))
            on_ref = np.sort(cam + truth['offset_ns'])  # no skew in these variants
            whole = np.array([whole_correlation_error(ref, on_ref, sigma_ns=s, start_ns=o)
                              for s in SIGMAS_NS for o in STARTS_NS]) / MS
            worst = np.maximum(worst, np.abs(whole))
            se = fit.uncertainty_ns / MS if fit.uncertainty_ns else float('nan')
            print(f'{seed:>4} {err / MS:>+9.3f} {se:>6.3f} | ' + ' '.join(f'{w:>+16.3f}' for w in whole))
        print(f'{"max":>4} {"":>9} {"":>6} | ' + ' '.join(f'{w:>16.3f}' for w in worst))


if __name__ == '__main__':
    main()
