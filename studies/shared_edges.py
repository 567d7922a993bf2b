"""What the virtual rigs' shared edges are worth to each method: the EVK4 rigs of
``bench/realrigs.py`` whose cameras start and stop at the same instant, as cut, and again with the
second camera's first and last 50 ms cut off, as two real cameras never start together.

    ./dev run python studies/shared_edges.py [--cut-ms 50] [--jobs 2]

Both virtual cameras of a rig come from one recording, so unless a case starts the second one late,
stops it early or cuts a gap, their recordings begin and end at the same true instant, often in the
middle of activity: two steps, from nothing to full activity and back, that line up at the true
offset. A method that reads the stretch before a camera's first event as "no activity" is led by
them. The plain NCC the issue compares against (``evsync_testing.virtual.plain_ncc``: 1 ms counts, the
camera's zero-padded) is such a method; the refined estimator pairs only bins both cameras recorded
(``schedule.coverage``, ``refined._recorded_spans``). The cases: ``bench/realrigs.py``'s ``evk4``
(parity and random splits) and ``resampled`` groups, less those with a late start, an early stop, a
gap or a cut (their edges do not line up already). Per case, as cut and with the ends cut: the plain
NCC's error, and the refined estimate's error, standard error (both at the middle of the camera's
recording, as the benchmark judges them) and whether it was accepted. A wrong answer, as in the
benchmark: accepted more than 5 ms or 5 standard errors off.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing

import numpy as np

from evsync_ros.core.engine.arrays import fit_camera
from evsync_ros.core.refined import RefinedParams
from evsync_ros.sim import simbag
from evsync_testing.realcases import evk4_cases, resampled_cases
from evsync_testing.realdata import read_events, real_data_dir
from evsync_testing.virtual import Case, plain_ncc, virtual_rig

MS = 1_000_000
_EVENTS: tuple[np.ndarray, ...] | None = None


def _one(job: tuple[Case, int]) -> tuple[str, list[float]]:
    """(name, [plain, refined, se, accepted] as cut, then the same with the camera's ends cut)."""
    global _EVENTS
    case, cut_ns = job
    if _EVENTS is None:
        (_EVENTS,) = read_events(real_data_dir() / 'evk4_hd').values()
    times, truth = virtual_rig(case, _EVENTS)
    ref, cam = times['/a'], times['/b']
    mid = int(np.median(cam))
    out: list[float] = []
    for cut in (0, cut_ns):
        kept = cam[(cam >= cam[0] + cut) & (cam <= cam[-1] - cut)]
        plain = plain_ncc(ref, kept)
        out.append(math.nan if plain is None else
                   simbag.error_ns({'offset_ns': plain, 'skew_ppm': 0.0, 'anchor_ns': 0}, truth, mid))
        fit = fit_camera(ref, kept, topic='/b', params=RefinedParams())
        se = fit.uncertainty_at(mid)
        out += [simbag.error_ns(fit.as_json(), truth, mid), math.nan if se is None else se, float(fit.accepted)]
    return f'{case.group} {case.name}', out


def _summary(label: str, rows: np.ndarray) -> str:
    plain, err, se, ok = (rows[:, k] for k in range(4))
    accepted = ok > 0
    z = np.abs(err[accepted]) / se[accepted]
    wrong = int(np.sum((np.abs(err[accepted]) > 5 * MS) | (z > 5)))
    return (f'{label}: plain NCC within 0.1 ms {int(np.sum(np.abs(plain) <= 0.1 * MS))} of {rows.shape[0]}, '
            f'median error {np.nanmedian(np.abs(plain)) / MS:.3f} ms | refined accepted {int(accepted.sum())}, '
            f'within 0.1 ms {int(np.sum(np.abs(err[accepted]) <= 0.1 * MS))}, within 3 se {int(np.sum(z <= 3))}, '
            f'wrong {wrong}, rms error {math.sqrt(float(np.mean(err[accepted] ** 2))) / MS:.3f} ms')


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--cut-ms', type=float, default=50.0, help="the second camera's ends cut off (ms)")
    ap.add_argument('--jobs', type=int, default=2)
    args = ap.parse_args()
    cases = [c for c in evk4_cases(False) + resampled_cases(False)
             if c.split != 'halves' and not (c.late_ns or c.early_ns or c.gap or c.cut_ns)]
    cut_ns = int(args.cut_ms * MS)
    with multiprocessing.Pool(args.jobs) as pool:
        results = pool.map(_one, [(c, cut_ns) for c in cases])
    print(f'error ms (plain NCC | refined: error, standard error, accepted), as cut | the camera\'s ends cut '
          f'{args.cut_ms:g} ms')
    for name, r in results:
        cells = []
        for k in (0, 4):
            plain, err, se, ok = r[k:k + 4]
            cells.append(f'{plain / MS:+9.3f} | {err / MS:+7.3f} {se / MS:6.3f} {"yes" if ok else "no":>3}')
        print(f'{name[:62]:<62} {cells[0]}  ||  {cells[1]}')
    rows = np.array([r for _, r in results])
    print(_summary('as cut', rows[:, :4]))
    print(_summary(f'ends cut {args.cut_ms:g} ms', rows[:, 4:]))


if __name__ == '__main__':
    main()
