"""Does the live node lock where the bag estimate accepts, on real recordings at the drivers' packet
rate? Issue 21's "one rule everywhere", measured on real data rather than the simulator.

    ./dev run python studies/live_real.py [--only parity random halves] [--ladder]

The virtual rigs of ``bench/realrigs.py``'s ``evk4`` and ``make`` groups that can be written as a
bag (``evsync_testing.virtualbag``: no jitter, noise or hot pixels, whose events have no pixel of the
recording), each written as the drivers send it (evt3, a packet a millisecond) and then:

* **offline**: ``evsync estimate`` on the bag (``estimate_bag``);
* **live**: the node at its defaults (``evsync_testing.nodefaults.Replay``: an ``EvsyncNode`` in this
  process, its message path fed each packet at its record time, its estimation and report timers
  run in recorded time, what it publishes received over DDS), its last report before the recording
  ends.

Each is judged as ``bench/realrigs.py`` judges: error at the middle of the camera's recording,
against its standard error there; **wrong** when accepted (live: locked) and more than 5 ms or 5
standard errors off. The rigs are 10.8 s long: the node has the recording once, in order, and must
lock from the windows it has seen so far. One case at a time (every replay uses the same topics).

``--ladder``: only the sensor's halves as arrays, searched as the node searches and as the bag's
first search does, with more or fewer windows (what is left between the two; docs/studies.md).
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from evsync_ros.bag.estimate import estimate_bag, read_event_times
from evsync_ros.core.engine import LIVE_SEARCH_NS
from evsync_ros.core.engine.arrays import fit_camera
from evsync_ros.core.refined import RefinedParams
from evsync_ros.sim.simbag import error_ns
from evsync_testing.nodefaults import Replay, read_messages
from evsync_testing.realcases import OFFSETS, evk4_cases, make_cases
from evsync_testing.realdata import read_events, real_data_dir
from evsync_testing.virtual import Case, virtual_rig
from evsync_testing.virtualbag import write_bag

MS = 1_000_000
WRONG_NS = 5 * MS
WRONG_SE = 5.0


def writable(case: Case) -> bool:
    return not (case.jitter_ns or case.noise or case.hot or case.step)


def _live(report: dict[str, str], cam: dict[str, Any], mid: int) -> tuple[bool, float, float, str]:
    """(locked, error ns, standard error ns at ``mid``, state or reason) of the node's last report."""
    locked = report['state'] == 'locked'
    why = report['state'] if locked else f"{report['state']}: {report['reason'] or report['message']}"
    if not report['offset_ns']:  # no estimate yet, not even a best guess
        return locked, math.nan, math.nan, why
    est = {'offset_ns': int(report['offset_ns']), 'skew_ppm': float(report['skew_ppm'] or 0.0),
           'anchor_ns': int(report['anchor_ns'] or 0)}
    se = math.nan
    if locked and report['uncertainty_ns']:
        skew_se = float(report['skew_uncertainty_ppm'] or 0.0)
        se = math.hypot(float(report['uncertainty_ns']), skew_se * 1e-6 * abs(mid - est['anchor_ns']))
    return locked, float(error_ns(est, cam, mid)), se, why


def run(case: Case, events: tuple[np.ndarray, ...], work: Path) -> dict[str, Any]:
    bag = work / 'rig'
    truth = write_bag(case, events, bag)
    cam = truth['cameras'][1]
    times, _ = read_event_times(bag, topics=[cam['topic']])
    mid = int(np.median(times[cam['topic']]))
    fit = estimate_bag(bag).rig.camera(cam['topic'])
    offline = (fit.accepted, float(error_ns(fit.as_json(), cam, mid)), fit.uncertainty_at(mid) or math.nan,
               'accepted' if fit.accepted else fit.reason)
    replay = Replay(truth)
    try:
        replay.feed(read_messages(bag))
        live = _live(replay.last(cam['topic']), cam, mid)
    finally:
        replay.close()
    return {'name': f'{case.group} {case.name}', 'offline': offline, 'live': live}


def wrong(accepted: bool, err: float, se: float) -> bool:
    return accepted and (abs(err) > WRONG_NS or (se > 0 and abs(err) > WRONG_SE * se))


def ladder(events: tuple[np.ndarray, ...]) -> None:
    """The sensor's halves as arrays, each centred 2 ms from the truth (as an arrival prior would
    centre it), searched within 0.5 s (the node's range) and 5 s (the bag's first search), with 5,
    10 and 20 windows wanted: how many agree, and whether the rule accepts."""
    print('sensor halves, arrays centred 2 ms from the truth: windows agreeing / windows, accepted, error us')
    for seed, offset in ((0, OFFSETS[0]), (2, OFFSETS[2]), (4, OFFSETS[4])):
        times, truth = virtual_rig(Case('study', 'halves', 'evk4_hd', 'halves', offset_ns=offset, seed=seed), events)
        ref, cam = np.sort(times['/a']), times['/b']
        mid = int(np.median(cam))
        cells = []
        for wanted in (5, 10, 20):
            for shift in (LIVE_SEARCH_NS, RefinedParams().max_shift_ns):
                fit = fit_camera(ref, cam, topic='/b', prior_ns=truth['offset_ns'] + 2 * MS,
                                 params=RefinedParams(max_shift_ns=shift, windows_wanted=wanted))
                err = error_ns(fit.as_json(), truth, mid) / 1e3
                agreeing = f'{fit.windows_agreeing:>2}/{fit.windows_total:<2}'
                verdict = 'yes' if fit.accepted else 'no '
                cells.append(f'{wanted:>2} windows +-{shift / 1e9:g} s: {agreeing} {verdict} {err:+9.1f}')
        print(f'seed {seed}:\n  ' + '\n  '.join(cells))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--only', nargs='+', help='only cases whose name has one of these words')
    ap.add_argument('--ladder', action='store_true',
                    help='only the sensor halves as arrays, by window count and search range (seconds)')
    args = ap.parse_args()
    (events,) = read_events(real_data_dir() / 'evk4_hd').values()
    if args.ladder:
        ladder(events)
        return
    cases = [c for c in evk4_cases(False) + make_cases(False) if writable(c)]
    if args.only:
        cases = [c for c in cases if any(w in c.name for w in args.only)]
    t0 = time.perf_counter()
    rows = []
    for case in cases:
        with tempfile.TemporaryDirectory() as tmp:
            rows.append(run(case, events, Path(tmp)))
    print(f'{len(rows)} virtual rigs of the real EVK4 recording, as evt3 at a packet a millisecond, '
          f'in {time.perf_counter() - t0:.0f} s\n')
    print(f'{"case":<62} {"offline err ms":>14} {"se":>6} {"acc":>3} | {"live err ms":>11} {"se":>6} {"lock":>4} | '
          f'why not')
    for r in rows:
        (oa, oe, ose, owhy), (la, le, lse, lwhy) = r['offline'], r['live']
        flags = ('  OFFLINE WRONG' if wrong(oa, oe, ose) else '') + ('  LIVE WRONG' if wrong(la, le, lse) else '')
        why = '; '.join(w for w in ((owhy if not oa else ''), (f'live {lwhy}' if not la else '')) if w)
        print(f'{r["name"][:62]:<62} {oe / MS:>+14.3f} {ose / MS:>6.3f} {"yes" if oa else "no":>3} | '
              f'{le / MS:>+11.3f} {lse / MS:>6.3f} {"yes" if la else "no":>4} | {why[:90]}{flags}')
    both = sum(r['offline'][0] and r['live'][0] for r in rows)
    only_off = sum(r['offline'][0] and not r['live'][0] for r in rows)
    only_live = sum(r['live'][0] and not r['offline'][0] for r in rows)
    apart = [abs(r['offline'][1] - r['live'][1]) / math.hypot(r['offline'][2], r['live'][2])
             for r in rows if r['offline'][0] and r['live'][0]]
    print(f'\n{len(rows)} rigs: accepted offline {both + only_off}, locked live {both + only_live}; both {both}, '
          f'offline only {only_off}, live only {only_live}. Wrong: offline '
          f'{sum(wrong(*r["offline"][:3]) for r in rows)}, live {sum(wrong(*r["live"][:3]) for r in rows)}. '
          f'Where both: the two apart by at most {max(apart, default=math.nan):.2f} of their combined standard '
          f'errors.')


if __name__ == '__main__':
    main()
