"""How the refined estimator's per-window offsets scatter with the width of its smoothing.

    ./dev run python studies/smoothing.py [--preset drift] [--seeds 10] [--smooth-us 500 1000 2000 3000 4000]
                                        [--fine-us 100]

Each recording of the preset is simulated once; every camera's events are taken in *true* time
(the simulator's times before any clock), so the right offset of every window is 0 and the right
skew is 0. For each smoothing sigma (``RefinedParams.smooth_ns``, the Gaussian over the camera's
fine counts), and for the default that picks one of several per window, every window of every
camera against the reference is fitted alone (``refined.fit_window``, no line, no second pass),
and the table gives:

* the per-window error: rms, median and largest |offset| over every window but each camera's first
  (a camera starts up to 1.5 s after the reference, so its first window overlaps only in part);
* the slope: a least-squares line through each camera's windows (after the first) against their
  centres, in ppm: the skew error those windows would give; rms and largest over the cameras.

This is how the default was chosen, and what it leaves: windows overlap by half and the scene
moves slowly, so their errors are not independent, and the slope error is larger than the
per-window error over the recording's span alone would give. The last line says how much of the
error two cameras share when they are measured against the same reference: the part that comes
from the reference's own events (in common) rather than each camera's.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import statistics
import sys
import time

import numpy as np

from evsync_ros.core.bins import SortedTimes
from evsync_ros.core.refined import RefinedParams, fit_window, window_starts
from evsync_ros.sim import pixelsim


def one(job: tuple[str, int, tuple, int]) -> dict:
    """Per sigma, each camera's window offsets (ns) and centres (s), on true times."""
    name, seed, sigmas, fine = job
    rig = pixelsim.preset(name, seed=seed)
    events = pixelsim.simulate(rig)
    ref_t = np.rint(events[rig.reference].true_t).astype(np.int64)
    ref = SortedTimes(ref_t)
    out: dict = {s: [] for s in sigmas}
    for cam in rig.cameras:
        if cam.topic == rig.reference:
            continue
        t = SortedTimes(np.rint(events[cam.topic].true_t).astype(np.int64))
        for sigma in sigmas:
            params = RefinedParams(smooth_ns=sigma, fine_ns=fine)
            starts, length = window_starts(ref_t, params)
            offsets = np.array([fit_window(ref, t, ref_start_ns=w, length_ns=length, prior_ns=0,
                                           params=params).offset_ns
                                for w in starts], dtype=np.float64)
            centres = (np.array(starts, dtype=np.float64) - starts[0] + length / 2) / 1e9
            out[sigma].append(np.stack([centres, offsets]))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--preset', default='drift', choices=list(pixelsim.PRESETS))
    ap.add_argument('--seeds', type=int, default=10)
    ap.add_argument('--jobs', type=int, default=2)
    ap.add_argument('--smooth-us', type=int, nargs='+', default=[500, 1000, 2000, 3000, 4000])
    ap.add_argument('--fine-us', type=int, default=RefinedParams().fine_ns // 1000,
                    help='fine bin width of the refinement (default: the estimator\'s)')
    args = ap.parse_args()
    # each alone, then the default choice
    sigmas = tuple(s * 1000 for s in args.smooth_us) + (RefinedParams().smooth_ns,)
    t0 = time.perf_counter()
    with multiprocessing.Pool(args.jobs) as pool:
        parts = pool.map(one, [(args.preset, s, sigmas, args.fine_us * 1000) for s in range(args.seeds)], chunksize=1)
    cams = len(parts[0][sigmas[0]])
    print(f'{args.preset}: {args.seeds} recordings, {cams} cameras each against the reference, true times, '
          f'in {time.perf_counter() - t0:.0f} s, {args.fine_us} us fine bins\n')
    head = (f'{"sigma us":>16} {"windows":>7} | {"window err rms us":>17} {"median":>7} {"max":>7} | '
            f'{"slope rms ppm":>13} {"max":>6}')
    print(head)
    print('-' * len(head))
    for sigma in sigmas:
        runs = [r for part in parts for r in part[sigma]]
        inner = np.concatenate([r[1, 1:] for r in runs]) / 1e3
        slopes = np.array([np.polyfit(r[0, 1:], r[1, 1:] / 1e3, 1)[0] for r in runs if r.shape[1] >= 3])
        slope = (f'{math.sqrt(float(np.mean(slopes ** 2))):13.2f} {float(np.abs(slopes).max()):6.2f}'
                 if slopes.size else f'{"-":>13} {"-":>6}')
        label = '/'.join(str(v // 1000) for v in sigma) + ' best' if isinstance(sigma, tuple) else str(sigma // 1000)
        print(f'{label:>16} {inner.size:7d} | {math.sqrt(float(np.mean(inner ** 2))):17.1f} '
              f'{float(np.median(np.abs(inner))):7.1f} {float(np.abs(inner).max()):7.1f} | {slope}')
    default = RefinedParams().smooth_ns
    shared = [float(np.corrcoef(part[default][0][1, 1:], part[default][1][1, 1:])[0, 1])
              for part in parts if len(part[default]) >= 2]
    if shared:
        print(f'\nwith the default, two cameras of one recording against the same reference: their window errors '
              f'correlate with r = {statistics.median(shared):.2f} (median over {len(shared)} recordings; '
              f'{min(shared):.2f} to {max(shared):.2f})')
    print('\nsigma: the Gaussian over the camera\'s fine counts; "best": the default, each window taking the one '
          'with the smallest jackknife standard error (a camera then keeps one smoothing for all its windows, '
          'core.refined.camera_result). window err: |offset| of each window fitted alone (truth 0), '
          'every camera\'s first window left out; '
          'slope: a least-squares line through a camera\'s windows (us per s = ppm).')
    return 0


if __name__ == '__main__':
    sys.exit(main())
