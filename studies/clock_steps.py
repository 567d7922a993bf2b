"""What the refined estimator makes of a camera whose clock jumps during the recording (a driver
restarted, a timestamp reset): where the jump is, and how large, against what is accepted.

    ./dev run python studies/clock_steps.py [--jobs 2]

Virtual rigs cut from the real EVK4 recording (10.8 s; ``evsync_testing.virtual``, ``step``):
the parity and random splits, the second camera's clock jumping by each size at each second of the
recording. One line cannot hold such a camera, so an accepted estimate is wrong for one side of the
jump; the agreement rule's clock-step check (``agreement._step``) is meant to say so instead. These
are in-memory arrays, with no arrival times: from a bag, a jump of 10 ms or more is also seen in
them (``core.host.clock_jumps``), wherever it is (docs/bags.md). Per
case: accepted or the reason's first words, and for an accepted one how far its line is off on each
side of the jump (at the middle of that side's events), in ms and in its standard errors there. An
accepted case counts as **wrong** when either side is more than 5 ms or 5 standard errors off, as
``bench/realrigs.py`` judges.
"""

from __future__ import annotations

import argparse
import multiprocessing
from dataclasses import replace
from typing import Any

import numpy as np

from evsync_ros.core.engine.arrays import fit_camera
from evsync_ros.core.refined import RefinedParams
from evsync_ros.sim import simbag
from evsync_testing.realdata import read_events, real_data_dir
from evsync_testing.virtual import Case, virtual_rig

MS = 1_000_000
S = 1_000_000_000
SIZES_NS = (2 * S, -700 * MS, 30 * MS, 3 * MS, 500_000)
AT_S = tuple(range(1, 11))
_EVENTS: tuple[np.ndarray, ...] | None = None


def _one(job: tuple[str, int, int]) -> dict[str, Any]:
    global _EVENTS
    split, at_s, by = job
    if _EVENTS is None:
        (_EVENTS,) = read_events(real_data_dir() / 'evk4_hd').values()
    case = Case('study', 'step', 'evk4_hd', split, offset_ns=37 * MS + 412_345, seed=1, step=(at_s * S, by))
    times, truth = virtual_rig(case, _EVENTS)
    ref, cam = times['/a'], times['/b']
    fit = fit_camera(ref, cam, topic='/b', params=RefinedParams())
    row: dict[str, Any] = {'split': split, 'at_s': at_s, 'by_ns': by, 'accepted': fit.accepted,
                           'reason': fit.reason.split(':')[0], 'sides': []}
    if fit.accepted:
        # each side's events on the camera's clock: the same rig without the jump, split where it is
        plain, _ = virtual_rig(replace(case, step=None), _EVENTS)
        k = 1 + case.skew_ppm * 1e-6
        at_clock = int(ref[0]) + round(at_s * S * k) - case.offset_ns  # the jump's instant, before it
        unstepped = plain['/b']
        for side, mask, shift in (('before', unstepped < at_clock, 0), ('after', unstepped >= at_clock, by)):
            if mask.sum() < 1000:
                continue
            mid = int(np.median(unstepped[mask])) + shift
            side_truth = dict(truth, offset_ns=truth['offset_ns'] - shift, anchor_ns=truth['anchor_ns'] + shift)
            err = simbag.error_ns(fit.as_json(), side_truth, mid)
            se = fit.uncertainty_at(mid) or float('nan')
            row['sides'].append((side, err, se))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--jobs', type=int, default=2)
    args = ap.parse_args()
    jobs = [(split, at, by) for split in ('parity', 'random') for by in SIZES_NS for at in AT_S]
    with multiprocessing.Pool(args.jobs) as pool:
        rows = pool.map(_one, jobs)
    wrong = 0
    print('clock jump of the second camera: accepted (line off before | after the jump, ms and standard errors), '
          'else the reason')
    for split in ('parity', 'random'):
        for by in SIZES_NS:
            cells = []
            for r in (r for r in rows if r['split'] == split and r['by_ns'] == by):
                if not r['accepted']:
                    cells.append(f'{r["at_s"]:>2}s {r["reason"]}')
                    continue
                bad = any(abs(e) > 5 * MS or abs(e) > 5 * se for _, e, se in r['sides'])
                wrong += bad
                sides = ' | '.join(f'{e / MS:+.3f} ({abs(e) / se:.0f} se)' for _, e, se in r['sides'])
                cells.append(f'{r["at_s"]:>2}s {"WRONG " if bad else ""}accepted {sides}')
            print(f'\n{split}, jump {by / MS:+g} ms:')
            print('\n'.join(f'  {c}' for c in cells))
    accepted = sum(r['accepted'] for r in rows)
    print(f'\n{len(rows)} cases: {accepted} accepted, {wrong} of them wrong (more than 5 ms or 5 standard errors '
          f'off on one side of the jump)')


if __name__ == '__main__':
    main()
