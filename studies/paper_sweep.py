"""How the paper-faithful estimator fares on the simple simulated rig: seeds x cases.

Each case is a pair of cameras with a start delay and a clock offset, 21 s long (two whole
10 s windows). Counts how often the method accepts within 0.5 ms, rejects (no window reached
min D < epsilon), accepts within the method's 1.5-bin resolution, or accepts a wrong offset.

    ./dev run python studies/paper_sweep.py [--seeds 10]
"""

from __future__ import annotations

import argparse

from evsync_ros.core import estimate_offset, paper
from evsync_ros.sim import rigsim

MS, S = 1_000_000, 1_000_000_000
CASES = {
    'camera starts 250 ms later': ([0, 250 * MS], [0, 0]),
    'camera starts 180 ms earlier': ([180 * MS, 0], [0, 0]),
    'zero': ([0, 0], [0, 0]),
    'clock +7.3 s, start +41 ms': ([0, 41 * MS], [0, 7_300 * MS]),
    'ROS time vs sensor time, +1.348 s': ([0, 1_348 * MS], [1_763_700_000 * S, 0]),
    'clock -6 s, start -77 ms': ([77 * MS, 0], [0, -6 * S]),
}


COLUMNS = ('<=0.5ms', '0.5-1.5ms', 'wrong', 'rejected')


def classify(est: paper.PaperEstimate, truth_ns: int) -> str:
    if not est.accepted:
        return 'rejected'
    err_ms = abs(est.offset_ns - truth_ns) / MS
    return '<=0.5ms' if err_ms <= 0.5 else '0.5-1.5ms' if err_ms <= 1.5 else 'wrong'


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seeds', type=int, default=10)
    args = ap.parse_args()
    print(f'{"case":<36} ' + ' '.join(f'{c:>9}' for c in COLUMNS) + f' {"max |err| accepted ms":>22}')
    totals = dict.fromkeys(COLUMNS, 0)
    for name, (delays, clocks) in CASES.items():
        counts = dict.fromkeys(COLUMNS, 0)
        worst = 0.0
        for seed in range(args.seeds):
            rig = rigsim.rig_from_start_delays(delays, clocks_ns=clocks, duration_ns=21 * S, seed=seed)
            streams = rigsim.simulate_streams(rig)
            ref, cam = (c.topic for c in rig.cameras)
            est = estimate_offset(streams[ref], streams[cam])
            truth = rig.true_offsets_ns()[cam]
            counts[classify(est, truth)] += 1
            if est.accepted:
                worst = max(worst, abs(est.offset_ns - truth) / MS)
        for c in COLUMNS:
            totals[c] += counts[c]
        print(f'{name:<36} ' + ' '.join(f'{counts[c]:>9}' for c in COLUMNS) + f' {worst:>22.3f}')
    print(f'{"all (" + str(args.seeds * len(CASES)) + " runs)":<36} ' + ' '.join(f'{totals[c]:>9}' for c in COLUMNS))


if __name__ == '__main__':
    main()
