"""Real recordings, virtual rigs with known answers: does evsync accept only right answers?

    ./dev run python bench/realrigs.py [--quick] [--jobs 2] [--only GROUP ...] [--live N] [--origins O ...]
                                       [--json FILE]

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

**Through the user's paths** (issue 37). The refined column above is the array API, which users do
not run. Each rig is also written as a bag as a host records it (``evsync_testing.virtualbag``: each camera
as the drivers send it, record times its host arrival times; the simulator's and the stereo rigs are
bags already; a noise event gets a random pixel, a hot pixel one of its own) and estimated by
``evsync estimate BAG --json`` in a process of its own (the **cli** columns). A sample of the rigs
written as bags (``--live N``, spread over the groups, run one at a time after the rest) is played at 1x into
``evsync_node`` with only topics, types and reference set (``evsync_testing.paths``), and judged on its last
report once the stream fell silent and the node decided on the windows its end allows (the **live**
columns: locked, error, standard error). Each path
is judged by the same wrong-answer rule; the summary counts wrong answers per path
(``wrong_by_path``) and where the paths decide differently (accepted by one and not the other, or
more than 3 combined standard errors apart: ``evsync_testing.paths.disagreements``).

**Bags of every origin** (issue 50). Each bag a rig is written as (one host's record times) is also
rewritten with the record times of every other origin a user has (``evsync_testing.origins``: each
camera's own clock, starting at zero at its first event; a second host whose clock runs 3.46 s ahead,
for every camera but the reference, its driver's stamps with it; each message's header.stamp, as a
converter writes it) and estimated by ``evsync estimate`` again, judged against that bag's truth by the
same rule (``--origins``). The summary counts cameras, accepted and wrong per origin (``by_origin``),
and a table names every camera whose verdict differs from one host's.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import shutil
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from evsync_ros.bag.estimate import estimate_bag
from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine.arrays import estimate_times
from evsync_ros.core.results import CameraFit, RigFit
from evsync_ros.sim import pixelsim, simbag
from evsync_testing import paths
from evsync_testing.origins import Origin, rewrite
from evsync_testing.origins import truth as origin_truth
from evsync_testing.realcases import (
    evk4_cases,
    front_cases,
    make_cases,
    resampled_cases,
    short_cases,
    sim_cases,
    stereo_cases,
)
from evsync_testing.realdata import missing, read_events, real_data_dir
from evsync_testing.virtual import Case, plain_ncc, virtual_rig
from evsync_testing.virtualbag import write_bag

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
    topic: str = '/cam1/events'
    """The camera's topic in the bag (``cli``, ``live``)."""
    cli: Judged | None = None
    """``evsync estimate BAG --json`` on the rig written as a bag (None: not written)."""
    live: Judged | None = None
    """``evsync_node`` fed the bag at 1x (None: not in the sample)."""
    apart: dict[str, list[str]] = field(default_factory=dict)
    """Where two paths decide differently ({'arrays/cli' or 'cli/live': what}; ``paths.disagreements``)."""
    origins: dict[str, Judged] = field(default_factory=dict)
    """``evsync estimate BAG --json`` on the bag rewritten with the record times of each other origin
    (``evsync_testing.origins``: each camera's clock, a second host, header.stamp), judged against the
    truth of that bag."""

    @property
    def wrong(self) -> bool:
        return _wrong(self.group, self.accepted, self.error_ns, self.se_ns)

    @property
    def cli_wrong(self) -> bool:
        return self.cli is not None and _wrong(self.group, self.cli.accepted, self.cli.error_ns, self.cli.se_ns)

    def origin_wrong(self, origin: str) -> bool:
        judged = self.cli if origin == Origin.HOST.value else self.origins.get(origin)
        return judged is not None and _wrong(self.group, judged.accepted, judged.error_ns, judged.se_ns)

    @property
    def live_wrong(self) -> bool:
        return self.live is not None and _wrong(self.group, self.live.accepted, self.live.error_ns, self.live.se_ns)


@dataclass
class Judged:
    """One path's verdict of one camera against the truth, at the middle of the camera's recording."""

    accepted: bool
    """Accepted (live: locked)."""
    error_ns: float | None
    se_ns: float | None
    reason: str
    messages: str = ''
    """Live: messages the node took of those played ('10761/10768')."""

    @classmethod
    def of(cls, verdict: paths.Verdict, truth: dict[str, Any], mid: int, messages: str = '') -> Judged:
        err, se = verdict.error_ns(truth, mid), verdict.se_at(mid)
        return cls(verdict.accepted, None if math.isnan(err) else err, None if math.isnan(se) else se,
                   verdict.reason, messages)


def _wrong(group: str, accepted: bool, error_ns: float | None, se_ns: float | None) -> bool:
    """Accepted and more than 5 ms, or more than 5 standard errors, off (stereo: 5 ms; ``paths.wrong``)."""
    return paths.wrong(accepted, error_ns, se_ns, within_se=math.inf if group == 'stereo' else WRONG_SE)


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
    row = Row(case.group, case.name, truth['offset_ns'], float(_error(refined, truth, mid)), refined['accepted'],
              _se(refined, mid), refined.get('reason', ''), float(_error(paper, truth, mid)), paper['accepted'],
              plain_err)
    if writable(case):
        with tempfile.TemporaryDirectory(prefix='evsync-realrigs-') as tmp:
            bag = Path(tmp) / 'rig'
            cam = write_bag(case, events, bag, **_geometry(case.source))['cameras'][1]
            row.topic = cam['topic']
            row.cli = _through_cli(bag, '/cam0/events', cam)
            row.origins = {o: found[cam['topic']] for o, found in _through_origins(bag, '/cam0/events', [cam]).items()}
    return [_compared(row)]


def writable(case: Case) -> bool:
    """Whether the case can be written as a bag (``evsync_testing.virtualbag``: all but a clock step, which no
    group here has)."""
    return not case.step


def _geometry(source: str) -> dict[str, int]:
    """The sensor of a recording, for its virtual rigs' bags (every event's pixel within it)."""
    x, y = _events(source)[1], _events(source)[2]
    return {'width': max(1280, int(x.max()) + 1), 'height': max(720, int(y.max()) + 1)}


def _through_cli(bag: Path, reference: str, cam: dict[str, Any]) -> Judged:
    """``evsync estimate BAG --json`` on the bag, judged against ``cam`` (the truth) at the middle of
    the camera's recording in the bag."""
    mid = paths.middles_of(paths.event_times(bag))[cam['topic']]
    return Judged.of(paths.through_cli(bag, reference=reference)[cam['topic']], cam, mid)


ORIGINS: list[Origin] = [o for o in Origin if o is not Origin.HOST]
"""The other origins each bag is rewritten with (``--origins``)."""


def _through_origins(bag: Path, reference: str, cams: list[dict[str, Any]]) -> dict[str, dict[str, Judged]]:
    """Per origin of ``ORIGINS``, the bag rewritten with its record times and estimated by ``evsync
    estimate``: each camera of ``cams`` (the truth of the bag as written) judged against its truth in
    the rewritten bag ({origin: {topic: judged}})."""
    out: dict[str, dict[str, Judged]] = {}
    for origin in ORIGINS:
        other = rewrite(bag, bag.with_name(f'{bag.name}-{origin.value}'), origin, reference=reference)
        try:
            found = paths.through_cli(other, reference=reference)
            middles = paths.middles_of(paths.event_times(other))
            out[origin.value] = {c['topic']: Judged.of(found[c['topic']], origin_truth(c, origin, reference=reference),
                                                       middles[c['topic']])
                                 for c in cams if c['topic'] != reference}
        finally:
            shutil.rmtree(other, ignore_errors=True)
    return out


def _compared(row: Row) -> Row:
    """Where the array path and the CLI decide differently (``paths.differ``, on their errors against
    the truth: each is on its own timeline)."""
    if row.cli is not None:
        found = paths.differ((row.accepted, row.error_ns or 0.0, row.se_ns or math.nan, row.reason),
                             (row.cli.accepted, row.cli.error_ns or 0.0, row.cli.se_ns or math.nan, row.cli.reason),
                             names=('arrays', 'cli'))
        if found:
            row.apart['arrays/cli'] = [found]
    if row.cli is not None and row.live is not None:
        found = paths.differ((row.cli.accepted, row.cli.error_ns or 0.0, row.cli.se_ns or math.nan, row.cli.reason),
                             (row.live.accepted, row.live.error_ns or 0.0, row.live.se_ns or math.nan,
                              row.live.reason), names=('cli', 'live'))
        if found:
            row.apart['cli/live'] = [found]
    return row


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
        row = Row(case.group, case.name, int(truth['offset_ns']), float(_error(r, truth, mid)), r['accepted'],
                  _se(r, mid), r.get('reason', ''), float(_error(p, truth, mid)), p['accepted'], plain_err,
                  topic='/right/events')
        verdict = paths.through_cli(bag, reference='/left/events')['/right/events']
        row.cli = Judged.of(verdict, truth, mid)
        row.origins = {o: found['/right/events'] for o, found in _through_origins(
            bag, '/left/events', [{**truth, 'topic': '/right/events'}]).items()}
        rows.append(row)  # estimate_bag is the CLI's path on the same bag: their rows are the same estimate
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
        cli = paths.through_cli(work / 'bag', reference=rig.reference)
        origins = _through_origins(work / 'bag', rig.reference, truth['cameras'])
        rows = []
        for cam in truth['cameras']:
            if cam['topic'] == rig.reference:
                continue
            mid = int(np.median(times[cam['topic']]))
            r, p = est['refined'].camera(cam['topic']).as_json(), est['paper'].camera(cam['topic']).as_json()
            plain = plain_ncc(times[rig.reference], times[cam['topic']])
            plain_err = None if plain is None else float(
                _error({'offset_ns': plain, 'skew_ppm': 0.0, 'anchor_ns': 0}, cam, mid))
            row = Row(case.group, f'{case.name} {cam["topic"]}', cam['offset_ns'],
                      float(_error(r, cam, mid)), r['accepted'], _se(r, mid), r.get('reason', ''),
                      float(_error(p, cam, mid)), p['accepted'], plain_err, topic=cam['topic'])
            row.cli = Judged.of(cli[cam['topic']], cam, mid)
            row.origins = {o: found[cam['topic']] for o, found in origins.items()}
            rows.append(_compared(row))
        return rows
    finally:
        shutil.rmtree(work, ignore_errors=True)


def run_case(case: Case) -> list[Row]:
    if case.split == 'stereo':
        return run_stereo_case(case)
    if case.split == 'sim':
        return run_sim_case(case)
    return run_array_case(case)


# --- the node, on a sample ---------------------------------------------------------------------------

def live_sample(cases: list[Case], n: int) -> list[Case]:
    """``n`` of the cases a bag is written for (not stereo: its record times are the real ones), spread
    over the groups: each group's in turn, every third of a group's first."""
    groups: dict[str, list[Case]] = {}
    for case in cases:
        if case.split == 'sim' or (case.split != 'stereo' and writable(case)):
            groups.setdefault(case.group, []).append(case)
    queues = [g[::3] + g[1::3] + g[2::3] for g in groups.values()]
    picked: list[Case] = []
    while len(picked) < n and any(queues):
        for queue in queues:
            if queue and len(picked) < n:
                picked.append(queue.pop(0))
    return picked


def run_live(case: Case) -> dict[str, Judged]:
    """The case written as a bag again and played into ``evsync_node`` at 1x: each camera's verdict,
    judged as the others are ({row name: judged})."""
    with tempfile.TemporaryDirectory(prefix='evsync-realrigs-') as tmp:
        bag = Path(tmp) / 'rig'
        if case.split == 'sim':
            rig = pixelsim.preset(case.preset, seed=case.seed)
            truth = simbag.write_rig(rig, pixelsim.simulate(rig), bag)
            named = {f'{case.name} {c["topic"]}': c for c in truth['cameras'] if c['topic'] != rig.reference}
        else:
            truth = write_bag(case, _events(case.source), bag, **_geometry(case.source))
            named = {case.name: truth['cameras'][1]}
        middles = paths.middles_of(paths.event_times(bag))
        run = paths.through_node(bag, reference=truth['reference'])
        out = {}
        for name, cam in named.items():
            taken = f'{run.received[cam["topic"]]}/{run.sent.get(cam["topic"], 0)}'
            out[name] = Judged.of(run.verdicts[cam['topic']], cam, middles[cam['topic']], messages=taken)
        return out


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
                'plain': rms_ms([r.plain_error_ns for r in resampled if r.plain_error_ns is not None])},
            **_paths_summary(rows)}


def _paths_summary(rows: list[Row]) -> dict[str, Any]:
    """What the bag and the CLI, and the node on its sample, decided: wrong answers by the same rule."""
    cli = [r for r in rows if r.cli is not None]
    live = [r for r in rows if r.live is not None]
    return {'cli_cases': len(cli), 'cli_accepted': sum(r.cli.accepted for r in cli if r.cli),
            'cli_wrong_accepted': sum(r.cli_wrong for r in cli), 'not_written': len(rows) - len(cli),
            'live_cases': len(live), 'live_locked': sum(r.live.accepted for r in live if r.live),
            'live_wrong_locked': sum(r.live_wrong for r in live),
            'live_cli_wrong_accepted': sum(r.cli_wrong for r in live),
            'wrong_by_path': {'arrays': sum(r.wrong for r in rows), 'cli': sum(r.cli_wrong for r in cli),
                              'live': sum(r.live_wrong for r in live)},
            'apart': {'arrays/cli': sum('arrays/cli' in r.apart for r in rows),
                      'cli/live': sum('cli/live' in r.apart for r in rows)},
            'by_origin': _by_origin(rows),
            'live_messages_not_taken': sum(int(b) - int(a) for r in live if r.live and r.live.messages
                                           for a, b in [r.live.messages.split('/')])}


def _by_origin(rows: list[Row]) -> dict[str, dict[str, int]]:
    """Per origin of the record times, over the rows written as bags: cameras, accepted, wrong accepted;
    and over the real recordings' rigs (not the simulator's), accepted."""
    out = {}
    for origin in Origin:
        judged = [(r, r.cli if origin is Origin.HOST else r.origins.get(origin.value)) for r in rows]
        judged = [(r, j) for r, j in judged if j is not None]
        out[origin.value] = {'cases': len(judged), 'accepted': sum(j.accepted for _, j in judged),
                             'wrong_accepted': sum(r.origin_wrong(origin.value) for r, _ in judged),
                             'real_accepted': sum(j.accepted for r, j in judged if r.group != 'sim')}
    return out


def origin_table(rows: list[Row]) -> str:
    """The cameras whose verdict differs between one host's record times and another origin's."""
    head = (f'{"group":<11} {"case":<58} {"origin":<13} {"host err ms":>11} {"acc":>3} | {"err ms":>9} {"acc":>3} '
            '| reason')
    lines = [head, '-' * len(head)]
    for r in rows:
        for origin, j in r.origins.items():
            if r.cli is None or (j.accepted == r.cli.accepted and not r.origin_wrong(origin)):
                continue
            flag = ' WRONG' if r.origin_wrong(origin) else ''
            lines.append(f'{r.group:<11} {r.name[:58]:<58} {origin:<13} {_ms(r.cli.error_ns):>11} '
                         f'{_yes(r.cli.accepted):>3} | {_ms(j.error_ns):>9} {_yes(j.accepted):>3} '
                         f'| {j.reason[:150]}{flag}')
    return '\n'.join(lines)


def _yes(accepted: bool) -> str:
    return 'yes' if accepted else 'no'


def table(rows: list[Row]) -> str:
    head = (f'{"group":<11} {"case":<58} {"refined err ms":>14} {"acc":>3} {"se ms":>8} | {"paper err ms":>12} '
            f'{"acc":>3} | {"plain err ms":>12} | {"cli err ms":>10} {"acc":>3} | reason')
    lines = [head, '-' * len(head)]
    for r in rows:
        flag = (' WRONG' if r.wrong else '') + (' CLI WRONG' if r.cli_wrong else '') + (
            ' APART (arrays/cli)' if 'arrays/cli' in r.apart else '')
        cli = f'{_ms(r.cli.error_ns):>10} {_yes(r.cli.accepted):>3}' if r.cli else f'{"not written":>14}'
        lines.append(f'{r.group:<11} {r.name[:58]:<58} {_ms(r.error_ns):>14} {_yes(r.accepted):>3} '
                     f'{_ms(r.se_ns).lstrip("+"):>8} | {_ms(r.paper_error_ns):>12} {_yes(r.paper_accepted):>3} '
                     f'| {_ms(r.plain_error_ns):>12} | {cli} | {r.reason}{flag}')
    return '\n'.join(lines)


def live_table(rows: list[Row]) -> str:
    """The node's sample: the CLI's verdict and the node's, side by side."""
    head = (f'{"group":<11} {"case":<58} {"cli err ms":>10} {"se ms":>6} {"acc":>3} | {"live err ms":>11} '
            f'{"se ms":>6} {"lock":>4} {"messages":>13} | why not')
    lines = [head, '-' * len(head)]
    for r in rows:
        if r.live is None or r.cli is None:
            continue
        c, v = r.cli, r.live
        flags = (' CLI WRONG' if r.cli_wrong else '') + (' LIVE WRONG' if r.live_wrong else '') + (
            ' APART' if 'cli/live' in r.apart else '')
        why = '; '.join(w for w in ((f'cli {c.reason}' if not c.accepted else ''),
                                    (f'live {v.reason}' if not v.accepted else '')) if w)
        lines.append(f'{r.group:<11} {r.name[:58]:<58} {_ms(c.error_ns):>10} {_ms(c.se_ns).lstrip("+"):>6} '
                     f'{_yes(c.accepted):>3} | {_ms(v.error_ns):>11} {_ms(v.se_ns).lstrip("+"):>6} '
                     f'{_yes(v.accepted):>4} {v.messages:>13} | {why[:100]}{flags}')
    return '\n'.join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--quick', action='store_true', help='fewer variants, one simulator seed')
    ap.add_argument('--jobs', type=int, default=2)
    ap.add_argument('--only', nargs='+',
                    help='only these groups (evk4 resampled make front evt3_short davis_short stereo sim)')
    ap.add_argument('--live', type=int, default=8, metavar='N',
                    help='play N of the rigs into evsync_node at 1x, one at a time (default 8; 0: none)')
    ap.add_argument('--json', help='also write every row and the summary to this file')
    ap.add_argument('--origins', nargs='*', default=[o.value for o in ORIGINS], metavar='ORIGIN',
                    help='record times each bag is also rewritten with and estimated from (default: '
                         f'{" ".join(o.value for o in ORIGINS)}; none: only one host\'s)')
    args = ap.parse_args()
    ORIGINS[:] = [Origin(o) for o in args.origins if o != Origin.HOST.value]
    root = real_data_dir()
    reason = missing(root, 'evk4_hd', 'evt3_sqlite3', 'libcaer_cmp_mcap', 'dvs128_stereo')
    if reason:
        raise SystemExit(reason)
    cases = (evk4_cases(args.quick) + resampled_cases(args.quick) + make_cases(args.quick)
             + front_cases(args.quick) + short_cases()
             + stereo_cases(args.quick) + sim_cases(args.quick))
    if args.only:
        cases = [c for c in cases if c.group in args.only]
    t0 = time.perf_counter()
    with multiprocessing.Pool(args.jobs) as pool:
        rows = [r for part in pool.map(run_case, cases, chunksize=1) for r in part]
    elapsed = time.perf_counter() - t0
    t1 = time.perf_counter()
    by_name = {(r.group, r.name): r for r in rows}
    sample = live_sample(cases, args.live)
    for case in sample:  # one at a time: the node runs in real time, and shares the cores with nothing else
        for name, judged in run_live(case).items():
            row = by_name[(case.group, name)]
            row.live = judged
            _compared(row)
    live_s = time.perf_counter() - t1
    print(f'{len(rows)} camera estimates from {len(cases)} virtual rigs in {elapsed:.0f} s; '
          f'{len(sample)} rigs played into the node in {live_s:.0f} s\n')
    print(table(rows))
    print(f'\nwhere another origin of the record times decides otherwise than one host\'s:\n{origin_table(rows)}')
    if sample:
        print(f'\nthe node\'s sample, played at 1x with only topics, types and reference set:\n{live_table(rows)}')
    summ = summary(rows)
    print()
    for group in dict.fromkeys(r.group for r in rows):
        part = summary([r for r in rows if r.group == group])
        print(f'{group:<11} cases {part["cases"]:>3}  accepted {part["accepted"]:>3}  wrong accepted '
              f'{part["wrong_accepted"]:>2}  within 3 se {part["within_3_se"]:>6}  plain solved '
              f'{part["plain_solved"]:>3}, of those accepted within 0.1 ms '
              f'{part["plain_solved_accepted_within_0.1ms"]:>3}'
              f'  paper wrong accepted {part["paper_wrong_accepted"]:>2}'
              f'  | cli accepted {part["cli_accepted"]:>3} of {part["cli_cases"]:>3}, wrong '
              f'{part["cli_wrong_accepted"]:>2}  | live locked {part["live_locked"]:>2} of {part["live_cases"]:>2}, '
              f'wrong {part["live_wrong_locked"]:>2}')
    for origin, part in summ['by_origin'].items():
        print(f'origin {origin:<13} cameras {part["cases"]:>3}  accepted {part["accepted"]:>3} (real rigs '
              f'{part["real_accepted"]:>3})  wrong accepted {part["wrong_accepted"]:>2}')
    print(f'\nall: {json.dumps(summ)}')
    print('\nwrong: accepted and more than 5 ms or 5 standard errors off (stereo: 5 ms, their own offset being '
          'unverified); plain solved: the plain NCC within 0.1 ms; within 3 se: the truth within 3 standard '
          'errors, over accepted cameras (stereo left out); ..._or_3se: within the target or within 3 standard '
          'errors (the wording proposed on issue 21); resampled_rms_ms: root mean square error over the resampled '
          'draws, the refined estimate\'s accepted ones and the plain NCC\'s. cli: evsync estimate on the rig written '
          'as a bag (not_written: cameras of rigs no bag was written for); live: evsync_node fed the bag at '
          '1x, its last report (locked counts as accepted); wrong_by_path: the wrong-answer rule on each path; '
          'apart: cameras on which two paths decide differently (accepted by one only, or more than 3 combined '
          'standard errors apart); live_messages_not_taken: messages played that the node never took.')
    if args.json:
        Path(args.json).write_text(json.dumps({'summary': summ, 'rows': [asdict(r) for r in rows]}, indent=1))
    wrong = any(summ['wrong_by_path'].values()) or any(p['wrong_accepted'] for p in summ['by_origin'].values())
    return 0 if not wrong else 1


if __name__ == '__main__':
    raise SystemExit(main())
