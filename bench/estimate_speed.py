"""Estimation speed: one estimate for 8 cameras over a 10 s window with a +-2 s search, the refined
estimator against the paper's brute-force traversal of D over the same +-2 s, in one run.

    ./dev run python bench/estimate_speed.py

Streams: 8 cameras seeing one bursty activity envelope (each its own Poisson thinning, about
200,000 events per camera in 12 s), offsets up to +-1.5 s. Times are the best of 5 runs after a
warm-up. The brute-force traversal evaluates D at every 1 ms shift in +-2 s (4,001 shifts) for each
of the 7 cameras, as the paper's Fig. 4 does over its range; the refined estimate covers the same
range by FFT, refines each to microseconds and scores its confidence.
"""

from __future__ import annotations

import os
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')  # as the evsync commands run (evsync_ros/__init__.py)

import numpy as np

from evsync_ros.core.density import event_density
from evsync_ros.core.engine.arrays import estimate_rig
from evsync_ros.core.paper import dissimilarity_curve
from evsync_ros.core.refined import RefinedParams

S = 1_000_000_000


def streams(seed=0):
    rng = np.random.default_rng(seed)
    ms = 20_000
    envelope = np.convolve(rng.random(ms) ** 6, np.ones(15) / 15, mode='same')
    n = rng.poisson(envelope * 200)
    t = np.sort(np.repeat(np.arange(ms, dtype=np.int64) * 1_000_000, n) + rng.integers(0, 1_000_000, n.sum()))
    offsets = [0] + rng.integers(-1_500_000_000, 1_500_000_000, 7).tolist()
    out = {}
    for i, off in enumerate(offsets):
        cam = t[rng.random(t.size) < 0.5] - off + 10**18
        out[f'/cam{i}'] = cam[(cam >= 10**18 + 3 * S) & (cam < 10**18 + 15 * S)]  # 12 s each
    return out, offsets


def best(fn, repeats=5):
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    data, offsets = streams()
    params = RefinedParams(max_shift_ns=2 * S, drift=False, window_ns=10 * S)
    ref = data['/cam0']

    def refined():
        return estimate_rig(data, reference='/cam0', params=params, consistency=False,
                            priors_ns={k: int(ref[0] - v[0]) for k, v in data.items()})

    def refined_checked():
        return estimate_rig(data, reference='/cam0', params=params, consistency=True,
                            priors_ns={k: int(ref[0] - v[0]) for k, v in data.items()})

    def brute():
        shifts = np.arange(-2000, 2001)
        m_ref, _ = event_density(ref, start_ns=int(ref[0]), bin_ns=1_000_000, n_bins=10_000)
        for k, cam in data.items():
            if k != '/cam0':
                m_cam, _ = event_density(cam, start_ns=int(cam[0]), bin_ns=1_000_000, n_bins=10_000)
                dissimilarity_curve(m_ref, m_cam, shifts)

    rig = refined()
    errors = [abs(c.offset_ns - off) / 1e3 for c, off in zip(rig.cameras, offsets)]
    t_ref = best(refined)
    t_chk = best(refined_checked, 3)
    t_brute = best(brute, 3)
    print(f'8 cameras, 10 s window, +-2 s search, {sum(v.size for v in data.values()):,} events in all')
    print(f'refined estimate (7 cameras against the reference): {t_ref * 1e3:8.1f} ms   '
          f'largest error {max(errors):.1f} us, all accepted: {all(c.accepted for c in rig.cameras)}')
    print(f'refined with the 21-pair consistency check:           {t_chk * 1e3:8.1f} ms')
    print(f"paper's brute-force traversal of D, same range:       {t_brute * 1e3:8.1f} ms   "
          f'({t_brute / t_ref:.1f}x the refined estimate)')
    # how each scales with the search range (the traversal is linear in it, the FFT nearly flat)
    wide = RefinedParams(max_shift_ns=5 * S, drift=False, window_ns=10 * S)
    t_ref5 = best(lambda: estimate_rig(data, reference='/cam0', params=wide, consistency=False,
                                       priors_ns={k: int(ref[0] - v[0]) for k, v in data.items()}), 3)
    shifts5 = np.arange(-5000, 5001)

    def brute5():
        m_ref, _ = event_density(ref, start_ns=int(ref[0]), bin_ns=1_000_000, n_bins=10_000)
        for k, cam in data.items():
            if k != '/cam0':
                m_cam, _ = event_density(cam, start_ns=int(cam[0]), bin_ns=1_000_000, n_bins=10_000)
                dissimilarity_curve(m_ref, m_cam, shifts5)
    t_brute5 = best(brute5, 3)
    print(f'with a +-5 s search: refined {t_ref5 * 1e3:.1f} ms, traversal {t_brute5 * 1e3:.1f} ms '
          f'({t_brute5 / t_ref5:.1f}x)')


if __name__ == '__main__':
    main()
