"""What the event-rate envelopes can tell at best: coherence between cameras, the Cramer-Rao floor
of any offset and skew estimate made from them, and why a slower camera's lag reads as an offset.

    ./dev run python studies/limits.py [--presets same-model mixed-models drift] [--seeds 3] [--jobs 2]

For each recording, every camera's events are counted in 50 us bins on *true* time (the simulator's
event times before any clock: a perfect estimator would find offset 0 and skew 0 on them) and
compared with the reference camera's:

* **coherence** gamma^2(f) by Welch's method (0.82 s Hann segments, half overlapping), debiased for
  the number of segments K: (K gamma^2 - 1) / (K - 1), clipped to [0, 0.999], below 500 Hz (the
  simulator steps every 1 ms and interpolates linearly within a step, which puts a comb at 1 kHz and
  its harmonics into every camera's envelope alike: an artefact of the simulator, left out);
* **delay information** per second of recording, J = 2 * integral (2 pi f)^2 gamma^2 / (1 - gamma^2) df
  (Knapp and Carter's bound for a delay between two jointly stationary signals observed for T
  seconds: var >= 1 / (J T)). The floor of one window's offset is sqrt(1 / (J T)) for T = 10 s;
  the floor of a skew fitted over a recording of L seconds with the information spread evenly is
  sqrt(12 / (J L^3)) (a line's slope);
* **delay by band**: the cross-spectrum's phase over each band divided by its mean angular frequency:
  a pure delay gives the same value in every band; a filter (a slower photoreceptor) gives a delay
  that changes with frequency. Where the values agree across the coherent band, the envelopes cannot
  tell the camera's lag from a clock offset;
* **refined**: the refined estimator's spread, the standard deviation of its per-window offsets on
  the same true-time streams (drift off), next to the floor for one window; and the slope of its
  line through them (the skew error it makes on a camera with no skew), next to the skew floor.

The floors assume what the bound assumes (stationary envelopes, Gaussian errors); they say what no
estimator working on these envelopes can beat on average, not what the estimator achieves.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import statistics
import sys
import time

import numpy as np

from evsync_ros.core.engine.arrays import fit_camera
from evsync_ros.core.refined import RefinedParams
from evsync_ros.sim import pixelsim

BIN_NS = 50_000
SEGMENT = 1 << 14
"""Welch segment: 16384 bins of 50 us, 0.82 s."""
BANDS_HZ = ((1, 5), (5, 10), (10, 20), (20, 40), (40, 80))
WINDOW_S = 10.0
GAMMA2_CAP = 0.999
MAX_HZ = 500.0
"""Frequencies used: below half the simulator's step rate (1 ms steps, linear within a step, put a
comb at 1 kHz and its harmonics into every camera's envelope alike: an artefact, left out)."""


def _segments(x: np.ndarray) -> np.ndarray:
    """Hann-windowed, mean-removed, half-overlapping segments' spectra (one row each)."""
    starts = range(0, x.size - SEGMENT + 1, SEGMENT // 2)
    w = np.hanning(SEGMENT)
    rows = np.stack([x[s:s + SEGMENT] - x[s:s + SEGMENT].mean() for s in starts]) * w
    return np.fft.rfft(rows, axis=1)


def pair_limits(ref_t: np.ndarray, cam_t: np.ndarray) -> dict:
    """Coherence, delay information and delay by band of two true-time event streams."""
    t0 = int(min(ref_t[0], cam_t[0]))
    n = int((max(ref_t[-1], cam_t[-1]) - t0) // BIN_NS) + 1
    a = np.bincount((ref_t - t0) // BIN_NS, minlength=n).astype(float)
    b = np.bincount((cam_t - t0) // BIN_NS, minlength=n).astype(float)
    fa, fb = _segments(a), _segments(b)
    k = fa.shape[0]
    saa = np.mean(np.abs(fa) ** 2, axis=0)
    sbb = np.mean(np.abs(fb) ** 2, axis=0)
    sab = np.mean(np.conj(fa) * fb, axis=0)
    f = np.fft.rfftfreq(SEGMENT, BIN_NS / 1e9)
    with np.errstate(invalid='ignore', divide='ignore'):
        raw = np.abs(sab) ** 2 / (saa * sbb)
    g2 = np.clip((k * np.nan_to_num(raw) - 1) / (k - 1), 0.0, GAMMA2_CAP)
    g2[(f <= 0) | (f >= MAX_HZ)] = 0.0  # the simulator's 1 ms step: a comb at 1 kHz common to every camera
    df = f[1] - f[0]
    info = 2 * float(np.sum((2 * np.pi * f) ** 2 * g2 / (1 - g2)) * df)  # per second of recording
    bands = {}
    for lo, hi in BANDS_HZ:
        m = (f >= lo) & (f < hi)
        # camera b lags a by d: b(t) = a(t - d), cross-spectrum conj(A) B has phase -2 pi f d
        phase = -float(np.angle(np.sum(sab[m])))
        bands[(lo, hi)] = (phase / (2 * np.pi * float(np.mean(f[m]))), float(np.mean(g2[m])))
    return {'info': info, 'bands': bands, 'coherent_hz': float(f[g2 >= 0.5].max()) if np.any(g2 >= 0.5) else 0.0}


def _ppm(v: float) -> str:
    return '-' if math.isnan(v) else f'{v:.2f} ppm'


def one(job):
    name, seed = job
    rig = pixelsim.preset(name, seed=seed)
    events = pixelsim.simulate(rig)
    ref = np.rint(events[rig.reference].true_t).astype(np.int64)
    duration_s = (int(ref[-1]) - int(ref[0])) / 1e9
    rows = []
    for cam in rig.cameras:
        if cam.topic == rig.reference:
            continue
        t = np.rint(events[cam.topic].true_t).astype(np.int64)
        lim = pair_limits(ref, t)
        params = RefinedParams(drift=False)
        fit = fit_camera(ref, t, topic=cam.topic, prior_ns=0, params=params)
        good = [w for w in fit.windows if w.accepted]
        offsets = [w.offset_ns for w in good]
        drifted = fit_camera(ref, t, topic=cam.topic, prior_ns=0, params=RefinedParams())
        slope = drifted.skew_ppm if drifted.accepted else math.nan
        rows.append({'preset': name, 'seed': seed, 'topic': cam.topic, 'duration_s': duration_s, **lim,
                     'window_floor_us': 1e6 / math.sqrt(lim['info'] * WINDOW_S) if lim['info'] > 0 else math.inf,
                     'skew_floor_ppm': (1e6 * math.sqrt(12 / (lim['info'] * duration_s ** 3)) if lim['info'] > 0
                                        else math.inf),
                     'refined_std_us': statistics.pstdev(offsets) / 1e3 if len(offsets) > 1 else math.nan,
                     'refined_mean_us': -statistics.mean(offsets) / 1e3 if offsets else math.nan,
                     'refined_slope_ppm': slope})
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--presets', nargs='+', default=['same-model', 'mixed-models', 'drift'])
    ap.add_argument('--seeds', type=int, default=3)
    ap.add_argument('--jobs', type=int, default=2)
    args = ap.parse_args()
    t0 = time.perf_counter()
    with multiprocessing.Pool(args.jobs) as pool:
        rows = [r for part in pool.map(one, [(p, s) for p in args.presets for s in range(args.seeds)], chunksize=1)
                for r in part]
    print(f'{len(rows)} camera pairs ({args.seeds} seeds per preset) in {time.perf_counter() - t0:.0f} s, true times, '
          f'50 us bins, Welch segments of {SEGMENT * BIN_NS / 1e9:.2f} s\n')
    band_head = ' '.join(f'{f"{lo}-{hi} Hz":>9}' for lo, hi in BANDS_HZ)
    head = (f'{"preset":13} {"camera":20} {"coh>=0.5 to":>11} {"window floor":>12} {"refined std":>11} '
            f'{"skew floor":>10} {"slope":>9} | lag by band, us: {band_head} | {"refined lag":>11}')
    print(head)
    print('-' * len(head))
    for r in rows:
        bands = ' '.join(f'{d * 1e6:9.0f}' if g >= 0.5 else f'{"(" + format(d * 1e6, ".0f") + ")":>9}'
                         for d, g in r['bands'].values())
        print(f'{r["preset"]:13} {r["topic"] + " s" + str(r["seed"]):20} {r["coherent_hz"]:8.0f} Hz '
              f'{r["window_floor_us"]:9.1f} us {r["refined_std_us"]:8.1f} us {r["skew_floor_ppm"]:6.2f} ppm '
              f'{_ppm(r["refined_slope_ppm"]):>9} | '
              f'{"":17} {bands} | {r["refined_mean_us"]:8.0f} us')
    print('\ncoh>=0.5 to: the highest frequency where the debiased coherence reaches 0.5; window floor: the '
          'Cramer-Rao floor of one 10 s window\'s offset (std); refined std: the spread of the refined '
          'estimator\'s per-window offsets on the same streams; skew floor: the floor of a skew fitted over '
          'the whole recording; slope: the refined estimator\'s line through its per-window offsets (the skew '
          'it would report for a camera with none); lag by band: the camera\'s delay behind the reference from the '
          'cross-spectrum\'s phase in each band (in brackets where the coherence is under 0.5); refined '
          'lag: the refined estimator\'s mean offset on true times (what it reads as a clock offset).')
    for p in args.presets:
        mine = [r for r in rows if r['preset'] == p]
        slopes = [r['refined_slope_ppm'] for r in mine if not math.isnan(r['refined_slope_ppm'])]
        fitted = (f'refined slope rms {math.sqrt(statistics.mean(v * v for v in slopes)):.2f} ppm (max '
                  f'{max(abs(v) for v in slopes):.2f})' if slopes else 'no drift line (recordings under 5 windows)')
        print(f'{p}: window floor median {statistics.median(r["window_floor_us"] for r in mine):.1f} us, refined std '
              f'median {statistics.median(r["refined_std_us"] for r in mine):.1f} us, skew floor median '
              f'{statistics.median(r["skew_floor_ppm"] for r in mine):.2f} ppm (max '
              f'{max(r["skew_floor_ppm"] for r in mine):.2f}), {fitted}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
