"""Real recordings, virtual rigs with known answers: does evsync accept only right answers?

    ./dev run python bench/realrigs.py [--quick] [--jobs 2] [--only GROUP ...] [--json FILE] [--markdown]

Every real recording in ``../shared/data/real`` (or ``$EVSYNC_REAL_DATA``) is cut into virtual rigs
whose true offsets are known, because both virtual cameras come from one sensor and one clock:

* **evk4**, the 10.8 s Prophesee EVK4 HD recording, split three ways: by pixel parity (two cameras
  seeing the same scene through interleaved pixels), into the sensor's left and right halves (two
  cameras seeing different parts of one scene), and into two random halves of the pixels. The
  second camera then gets, case by case: an offset from 1 ms to +-4 s, a skew to +-100 ppm,
  thinning, background noise, hot pixels, latency jitter, a late start, an early stop, a gap, or
  the whole rig cut short.
* **resampled**: the EVK4 variants whose error is mostly noise (1 ms of latency jitter; thinning,
  noise and 0.3 ms of jitter), on the parity and random splits, each drawn with ten fresh seeds:
  whether the stated errors hold is a question of how often, which one draw cannot answer.
* **make**: the EVK4 split, its second camera a coarser, less sensitive camera of another make
  (``virtual.coarser``): 2x2 or 4x4 of the recording's pixels pooled into one, firing once per 2-4
  of their events, with a refractory period; on the parity and random splits, with a late start,
  jitter and a skew on top, and on the sensor's halves (which must not be accepted).
* **evt3_short**, **davis_short**: the 2 s Prophesee and 1 s DAVIS346 recordings, split by parity,
  with offsets: recordings too short for some methods.
* **stereo**: the three DVS128 stereo pairs (two real retinas on one rig), through the bag tools:
  the right camera restamped by a known shift (``restamp_bag``), then estimated from the bag. Their
  own offset is unverified: about 0, a few ms at most, their README says. So the truth is taken as
  the shift, and a case counts as wrong when the estimate is more than 5 ms from it.
* **sim**: every simulator preset, through a rosbag2 and the adapters (``evsync estimate``'s path).

For each case: the refined estimator (the default), the paper's method, and a plain NCC (1 ms
counts over one window of at most 10 s, mean-removed and normalised over each lag's overlap, +-3 s
around the first-event prior, lags keeping half the window, a parabola through the peak), each
judged against the truth at the middle of the camera's recording, and the refined one against its
standard error there (the offset's at the anchor, and the skew's over the distance from it). A
refined answer is **wrong** when it is accepted and more than 5 ms, or more than 5 standard errors,
off (stereo: 5 ms).
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from evsync_ros.bag.estimate import estimate_bag, estimate_times
from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.results import CameraFit, RigFit
from evsync_ros.sim import pixelsim, simbag
from evsync_ros.testing.realcases import (
    evk4_cases,
    make_cases,
    resampled_cases,
    short_cases,
    sim_cases,
    stereo_cases,
)
from evsync_ros.testing.realdata import missing, read_events, real_data_dir
from evsync_ros.testing.virtual import Case, plain_ncc, virtual_rig

MS = 1_000_000
S = 1_000_000_000
WRONG_NS = 5 * MS
WRONG_SE = 5.0
PLAIN_SOLVED_NS = 100_000
"""A case the plain NCC solves: within 0.1 ms."""


def _error(est: dict[str, Any], truth: dict[str, Any], at_ns: int) -> int:
    return simbag.error_ns(est, truth, at_ns)


@dataclass
class Row:
    group: str
    name: str
    truth_ns: int
    error_ns: float | None
    accepted: bool
    se_ns: float | None
    reason: str
    paper_error_ns: float | None
    paper_accepted: bool
    plain_error_ns: float | None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def wrong(self) -> bool:
        if not self.accepted or self.error_ns is None:
            return False
        off = abs(self.error_ns)
        if self.group == 'stereo':
            return off > WRONG_NS
        return off > WRONG_NS or (self.se_ns is not None and self.se_ns > 0 and off > WRONG_SE * self.se_ns)


def _camera(rig: RigFit, topic: str) -> dict[str, Any]:
    return rig.camera(topic).as_json()


def _se(cam: dict[str, Any], at_ns: int) -> float | None:
    """The standard error of the offset the estimate gives at camera time ``at_ns``, where its error
    is judged (``CameraFit.uncertainty_at``)."""
    return CameraFit.from_json(cam).uncertainty_at(at_ns)


def run_array_case(case: Case) -> list[Row]:
    events = _events(case.source)
    times, truth = virtual_rig(case, events)
    mid = int(np.median(times['/b']))
    refined = _camera(estimate_times(times, reference='/a', method='refined', consistency=False), '/b')
    paper = _camera(estimate_times(times, reference='/a', method='paper', consistency=False), '/b')
    plain = plain_ncc(times['/a'], times['/b'])
    plain_err = None if plain is None else float(_error({'offset_ns': plain, 'skew_ppm': 0.0, 'anchor_ns': 0},
                                                      truth, mid))
    return [Row(case.group, case.name, truth['offset_ns'], float(_error(refined, truth, mid)), refined['accepted'],
                _se(refined, mid), refined.get('reason', ''), float(_error(paper, truth, mid)), paper['accepted'],
                plain_err)]


_EVENTS: dict[str, tuple[np.ndarray, ...]] = {}


def _events(source: str) -> tuple[np.ndarray, ...]:
    if source not in _EVENTS:
        (ev,) = read_events(real_data_dir() / source).values()
        _EVENTS[source] = ev
    return _EVENTS[source]


def run_stereo_case(case: Case) -> list[Row]:
    src = real_data_dir() / case.source
    work = Path(tempfile.mkdtemp(prefix='evsync-realrigs-'))
    try:
        bag = work / 'shifted'
        # the right camera on a clock case.offset_ns behind: its times minus the shift
        restamp_bag(src, bag, corrections={'/right/events': ClockCorrection(offset_ns=-case.offset_ns),
                                           '/left/events': ClockCorrection()},
                    reference='/left/events', record_time='keep')
        truth = {'offset_ns': case.offset_ns, 'skew_ppm': 0.0, 'anchor_ns': 0}
        rows = []
        est = {m: estimate_bag(bag, reference='/left/events', method=m).rig.camera('/right/events').as_json()
               for m in ('refined', 'paper')}
        from evsync_ros.bag.estimate import read_event_times
        times, _ = read_event_times(bag)
        mid = int(np.median(times['/right/events']))
        plain = plain_ncc(times['/left/events'], times['/right/events'])
        plain_err = None if plain is None else float(_error({'offset_ns': plain, 'skew_ppm': 0.0, 'anchor_ns': 0},
                                                          truth, mid))
        r, p = est['refined'], est['paper']
        rows.append(Row(case.group, case.name, int(truth['offset_ns']), float(_error(r, truth, mid)), r['accepted'],
                        _se(r, mid), r.get('reason', ''), float(_error(p, truth, mid)), p['accepted'], plain_err))
        return rows
    finally:
        shutil.rmtree(work, ignore_errors=True)


def run_sim_case(case: Case) -> list[Row]:
    work = Path(tempfile.mkdtemp(prefix='evsync-realrigs-'))
    try:
        rig = pixelsim.preset(case.preset, seed=case.seed)
        truth = simbag.write_rig(rig, pixelsim.simulate(rig), work / 'bag')
        from evsync_ros.bag.estimate import read_event_times
        times, _ = read_event_times(work / 'bag')
        est = {m: estimate_bag(work / 'bag', reference=rig.reference, method=m).rig for m in ('refined', 'paper')}
        rows = []
        for cam in truth['cameras']:
            if cam['topic'] == rig.reference:
                continue
            mid = int(np.median(times[cam['topic']]))
            r, p = est['refined'].camera(cam['topic']).as_json(), est['paper'].camera(cam['topic']).as_json()
            plain = plain_ncc(times[rig.reference], times[cam['topic']])
            plain_err = None if plain is None else float(
                _error({'offset_ns': plain, 'skew_ppm': 0.0, 'anchor_ns': 0}, cam, mid))
            rows.append(Row(case.group, f'{case.name} {cam["topic"]}', cam['offset_ns'],
                            float(_error(r, cam, mid)), r['accepted'], _se(r, mid), r.get('reason', ''),
                            float(_error(p, cam, mid)), p['accepted'], plain_err))
        return rows
    finally:
        shutil.rmtree(work, ignore_errors=True)


def run_case(case: Case) -> list[Row]:
    if case.split == 'stereo':
        return run_stereo_case(case)
    if case.split == 'sim':
        return run_sim_case(case)
    return run_array_case(case)


# --- reporting -------------------------------------------------------------------------------------

def _ms(v: float | None) -> str:
    return '-' if v is None or not math.isfinite(v) else f'{v / MS:+.3f}'


def summary(rows: list[Row]) -> dict[str, Any]:
    accepted = [r for r in rows if r.accepted]
    wrong = [r for r in rows if r.wrong]
    judged = [r for r in accepted if r.se_ns and r.error_ns is not None and r.group != 'stereo']
    within3 = sum(abs(r.error_ns) <= 3 * r.se_ns for r in judged)
    solved = [r for r in rows if r.plain_error_ns is not None and abs(r.plain_error_ns) <= PLAIN_SOLVED_NS]
    solved_ok = [r for r in solved if r.accepted and r.error_ns is not None and abs(r.error_ns) <= PLAIN_SOLVED_NS]
    parity = [r for r in rows if r.group == 'evk4' and r.name.startswith('parity')]
    parity_ok = [r for r in parity if r.accepted and r.error_ns is not None and abs(r.error_ns) <= 50_000]
    paper_wrong = [r for r in rows if r.paper_accepted and r.paper_error_ns is not None
                   and abs(r.paper_error_ns) > WRONG_NS]
    # the wording proposed on issue 21: within the target, or within 3 of its stated errors where the
    # data's noise or a camera's latency bound it
    solved_or_3se = [r for r in solved if r.accepted and r.error_ns is not None and r.se_ns
                     and abs(r.error_ns) <= max(PLAIN_SOLVED_NS, 3 * r.se_ns)]
    parity_or_3se = [r for r in parity if r.accepted and r.error_ns is not None and r.se_ns
                     and abs(r.error_ns) <= max(50_000, 3 * r.se_ns)]
    resampled = [r for r in rows if r.group == 'resampled']

    def rms_ms(errors: list[float]) -> float | None:
        return math.sqrt(sum(e * e for e in errors) / len(errors)) / MS if errors else None
    return {'cases': len(rows), 'accepted': len(accepted), 'wrong_accepted': len(wrong),
            'right_accepted': len(accepted) - len(wrong),
            'within_3_se': f'{within3}/{len(judged)}' if judged else '-',
            'within_3_se_fraction': within3 / len(judged) if judged else None,
            'plain_solved': len(solved), 'plain_solved_accepted_within_0.1ms': len(solved_ok),
            'evk4_parity': len(parity), 'evk4_parity_within_0.05ms': len(parity_ok),
            'paper_wrong_accepted': len(paper_wrong),
            'plain_solved_accepted_within_0.1ms_or_3se': len(solved_or_3se),
            'evk4_parity_within_0.05ms_or_3se': len(parity_or_3se),
            'resampled_rms_ms': {
                'refined_accepted': rms_ms([r.error_ns for r in resampled if r.accepted and r.error_ns is not None]),
                'plain': rms_ms([r.plain_error_ns for r in resampled if r.plain_error_ns is not None])}}


def table(rows: list[Row]) -> str:
    head = (f'{"group":<11} {"case":<58} {"refined err ms":>14} {"acc":>3} {"se ms":>8} | {"paper err ms":>12} '
            f'{"acc":>3} | {"plain err ms":>12} | reason')
    lines = [head, '-' * len(head)]
    for r in rows:
        flag = ' WRONG' if r.wrong else ''
        acc, paper_acc = ('yes' if r.accepted else 'no'), ('yes' if r.paper_accepted else 'no')
        lines.append(f'{r.group:<11} {r.name[:58]:<58} {_ms(r.error_ns):>14} {acc:>3} '
                     f'{_ms(r.se_ns).lstrip("+"):>8} | {_ms(r.paper_error_ns):>12} {paper_acc:>3} '
                     f'| {_ms(r.plain_error_ns):>12} | {r.reason}{flag}')
    return '\n'.join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--quick', action='store_true', help='fewer variants, one simulator seed')
    ap.add_argument('--jobs', type=int, default=2)
    ap.add_argument('--only', nargs='+',
                    help='only these groups (evk4 resampled make evt3_short davis_short stereo sim)')
    ap.add_argument('--json', help='also write every row and the summary to this file')
    args = ap.parse_args()
    root = real_data_dir()
    reason = missing(root, 'evk4_hd', 'evt3_sqlite3', 'libcaer_cmp_mcap', 'dvs128_stereo')
    if reason:
        raise SystemExit(reason)
    cases = (evk4_cases(args.quick) + resampled_cases(args.quick) + make_cases(args.quick) + short_cases()
             + stereo_cases(args.quick) + sim_cases(args.quick))
    if args.only:
        cases = [c for c in cases if c.group in args.only]
    t0 = time.perf_counter()
    with multiprocessing.Pool(args.jobs) as pool:
        rows = [r for part in pool.map(run_case, cases, chunksize=1) for r in part]
    elapsed = time.perf_counter() - t0
    print(f'{len(rows)} camera estimates from {len(cases)} virtual rigs in {elapsed:.0f} s\n')
    print(table(rows))
    summ = summary(rows)
    print()
    for group in dict.fromkeys(r.group for r in rows):
        part = summary([r for r in rows if r.group == group])
        print(f'{group:<11} cases {part["cases"]:>3}  accepted {part["accepted"]:>3}  wrong accepted '
              f'{part["wrong_accepted"]:>2}  within 3 se {part["within_3_se"]:>6}  plain solved '
              f'{part["plain_solved"]:>3}, of those accepted within 0.1 ms '
              f'{part["plain_solved_accepted_within_0.1ms"]:>3}'
              f'  paper wrong accepted {part["paper_wrong_accepted"]:>2}')
    print(f'\nall: {json.dumps(summ)}')
    print('\nwrong: accepted and more than 5 ms or 5 standard errors off (stereo: 5 ms, their own offset being '
          'unverified); plain solved: the plain NCC within 0.1 ms; within 3 se: the truth within 3 standard '
          'errors, over accepted cameras (stereo left out); ..._or_3se: within the target or within 3 standard '
          'errors (the wording proposed on issue 21); resampled_rms_ms: root mean square error over the resampled '
          'draws, the refined estimate\'s accepted ones and the plain NCC\'s.')
    if args.json:
        Path(args.json).write_text(json.dumps({'summary': summ, 'rows': [r.__dict__ for r in rows]}, indent=1))
    return 0 if summ['wrong_accepted'] == 0 else 1


if __name__ == '__main__':
    raise SystemExit(main())
