"""How the refined estimator's skew error falls with the length of the recording.

    ./dev run python studies/skew_length.py [--durations 60 90 120 180] [--seeds 10] [--jobs 2]

The drift preset (same-model cameras whose clocks run tens of ppm fast or slow) at each length,
end to end as in ``bench/accuracy.py``: simulate, write a rosbag2, decode it, estimate with the
refined method. For every non-reference camera, the skew error is |estimated - true| ppm; the
offset error is where the camera's middle event lands on the reference timeline against the truth.

Issue 7 asks for skew within 1 ppm on recordings of 60 s or more. The windows' own errors do not
shrink with the length; what does is the lever arm of the line through them, and the number of
stretches of scene whose lags wander apart (see docs/studies.md, "What the envelopes can tell").
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import statistics
import sys
import time

import numpy as np

from evsync_ros.core.engine.arrays import estimate_times
from evsync_ros.sim import simbag
from evsync_testing.rigs import recorded


def one(job: tuple[int, float]) -> list[dict]:
    seed, duration = job
    rig, _, truth, times = recorded('drift', seed, duration)
    fit = estimate_times(times, reference=rig.reference, method='refined', consistency=False)
    rows = []
    for cam in truth['cameras']:
        if cam['topic'] == rig.reference:
            continue
        est = next(c for c in fit.cameras if c.topic == cam['topic'])
        mid = int(np.median(times[cam['topic']]))
        rows.append({'duration': duration, 'accepted': est.accepted, 'true_skew': cam['skew_ppm'],
                     'skew_err': est.skew_ppm - cam['skew_ppm'],
                     'offset_err_us': simbag.error_ns(est.as_json(), cam, mid) / 1e3,
                     'windows': sum(w.accepted for w in est.windows)})
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--durations', type=float, nargs='+', default=[60.0, 90.0, 120.0, 180.0])
    ap.add_argument('--seeds', type=int, default=10)
    ap.add_argument('--jobs', type=int, default=2)
    args = ap.parse_args()
    t0 = time.perf_counter()
    jobs = [(s, d) for d in args.durations for s in range(args.seeds)]
    with multiprocessing.Pool(args.jobs) as pool:
        rows = [r for part in pool.map(one, jobs, chunksize=1) for r in part]
    print(f'drift preset, {args.seeds} seeds per length, refined estimator, end to end through rosbag2, '
          f'in {time.perf_counter() - t0:.0f} s\n')
    head = (f'{"length s":>8} {"cameras":>7} {"rej":>4} {"windows":>7} | {"skew err rms ppm":>16} {"median":>7} '
            f'{"max":>6} {"<= 1 ppm":>8} | {"offset err mean us":>18} {"max":>6}')
    print(head)
    print('-' * len(head))
    for d in args.durations:
        mine = [r for r in rows if r['duration'] == d]
        ok = [r for r in mine if r['accepted']]
        if not ok:
            print(f'{d:8.0f} {len(mine):7d} {len(mine):4d}  (none accepted)')
            continue
        skew = np.abs([r['skew_err'] for r in ok])
        off = np.abs([r['offset_err_us'] for r in ok])
        print(f'{d:8.0f} {len(mine):7d} {len(mine) - len(ok):4d} {statistics.median(r["windows"] for r in ok):7.0f} | '
              f'{math.sqrt(float(np.mean(skew ** 2))):16.2f} {float(np.median(skew)):7.2f} {float(skew.max()):6.2f} '
              f'{f"{int(np.sum(skew <= 1.0))}/{skew.size}":>8} | {float(off.mean()):18.1f} {float(off.max()):6.1f}')
    print('\nskew err: |estimated - true| over accepted cameras; windows: the median number of accepted windows '
          'per camera; offset err: where the camera\'s middle event lands on the reference timeline.')
    return 0


if __name__ == '__main__':
    sys.exit(main())
