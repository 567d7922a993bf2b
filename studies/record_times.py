"""When do a bag's record times behave as one clock's arrivals? (issue 50)

    ./dev run python studies/record_times.py [--quick] [--jobs 2]

Rigs with a known answer (the EVK4 splits and the short real recordings of ``bench/realrigs.py``, the
simulator's presets, the real DVS128 stereo pairs) written as one host records them, then rewritten with
the record times of every origin (``evsync_testing.origins``: one host, each camera's own clock, a second
host seconds ahead, header.stamp as the record time). Per camera and origin:

* **prior err**: where the camera's arrival-lag line puts it (``engine.arrival.prior_ns``, the search's
  centre) less the truth, at the middle of its recording: what a search around record times starts from;
* **lag scatter**: each message's lag (record time less its last event) above its stream's lag line, as
  the engine follows it (``engine.arrival.ArrivalTrack``): median and 99th percentile, and the share of
  messages more than 1 ms below the line;
* **found - prior**: where the windows' line lies from the prior, for the accepted cameras.

The thresholds of ``core/engine/evidence.py`` come from this table (docs/studies.md, "Record times").
"""

from __future__ import annotations

import argparse
import multiprocessing
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from evsync_ros.bag.estimate import estimate_bag
from evsync_ros.bag.reader import BagReader
from evsync_ros.core.engine.arrival import ArrivalTrack, prior_ns
from evsync_ros.sim import pixelsim, simbag
from evsync_testing.origins import Origin, rewrite, truth
from evsync_testing.realcases import evk4_cases, short_cases
from evsync_testing.realdata import read_events, real_data_dir
from evsync_testing.virtualbag import write_bag
from msg_adapters.registry import decoder_for, is_event_type

MS = 1_000_000


def _lags(bag: Path) -> tuple[dict[str, ArrivalTrack], dict[str, list[float]], dict[str, list[int]]]:
    """Each event topic's lag line fed as the engine feeds it, the residuals of its messages above the
    line as they came, and its event times (for the middle)."""
    tracks: dict[str, ArrivalTrack] = {}
    resid: dict[str, list[float]] = {}
    times: dict[str, list[int]] = {}
    with BagReader(bag) as reader:
        decoders = {c.topic: decoder_for(c.msgtype) for c in reader.connections if is_event_type(c.msgtype)}
        for conn, record, raw in reader.messages(list(decoders)):
            t = decoders[conn.topic].decode(raw)[1].t
            if not t.size:
                continue
            track = tracks.setdefault(conn.topic, ArrivalTrack(jump_ns=1_000_000_000, reach_ns=10_000_000_000))
            if track.base_ns is not None and track.messages >= 8:
                resid.setdefault(conn.topic, []).append(record - int(t[-1]) - float(track.lag_at(record) or 0))
            track.add(record, int(t[-1]))
            times.setdefault(conn.topic, []).append(int(t[len(t) // 2]))
    return tracks, resid, times


def _rows(name: str, bag: Path, cams: list[dict[str, Any]], reference: str) -> list[dict[str, Any]]:
    out = []
    work = bag.parent
    for origin in Origin:
        src = bag if origin is Origin.HOST else rewrite(bag, work / f'rig-{origin.value}', origin, reference=reference)
        tracks, resid, times = _lags(src)
        est = estimate_bag(src, reference=reference).rig
        for cam in cams:
            topic = cam['topic']
            if topic == reference:
                continue
            true = truth(cam, origin, reference=reference)
            mid = int(np.median(times[topic]))
            want = true['offset_ns'] + true['skew_ppm'] * 1e-6 * (mid - true['anchor_ns'])
            prior = prior_ns(tracks[topic], tracks[reference], grid_ns=100_000)
            r = np.asarray(resid.get(topic, [0.0]))
            fit = est.camera(topic)
            found = fit.offset_ns + fit.skew_ppm * 1e-6 * (mid - fit.anchor_ns)
            out.append({'rig': name, 'camera': topic, 'origin': origin.value,
                        'prior_err_ms': None if prior is None else (prior - want) / MS,
                        'scatter_median_ms': float(np.median(r)) / MS,
                        'scatter_p99_ms': float(np.percentile(r, 99)) / MS,
                        'below_1ms': float(np.mean(r < -MS)), 'accepted': fit.accepted,
                        'found_minus_prior_ms': (found - prior) / MS if fit.accepted and prior is not None else None,
                        'error_ms': (found - want) / MS, 'reason': fit.reason[:60]})
    return out


def run(case: Any) -> list[dict[str, Any]]:
    work = Path(tempfile.mkdtemp(prefix='evsync-origins-'))
    try:
        bag = work / 'rig'
        if isinstance(case, str):  # a simulator preset
            rig = pixelsim.preset(case, seed=0, duration_s=20.0)
            found = simbag.write_rig(rig, pixelsim.simulate(rig), bag)
            return _rows(f'sim {case}', bag, found['cameras'], rig.reference)
        (events,) = read_events(real_data_dir() / case.source).values()
        geometry = {'width': max(1280, int(events[1].max()) + 1), 'height': max(720, int(events[2].max()) + 1)}
        found = write_bag(case, events, bag, **geometry)
        return _rows(f'{case.group} {case.name}', bag, found['cameras'], found['reference'])
    finally:
        shutil.rmtree(work, ignore_errors=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--quick', action='store_true')
    ap.add_argument('--jobs', type=int, default=2)
    args = ap.parse_args()
    cases: list[Any] = [c for c in evk4_cases(True) if 'clean' in c.name or 'late' in c.name] + short_cases()
    cases += ['mixed-models', 'bursty', 'drift', 'same-model'] if not args.quick else ['mixed-models']
    with multiprocessing.Pool(args.jobs) as pool:
        rows = [r for part in pool.map(run, cases, chunksize=1) for r in part]
    head = (f'{"rig":<44} {"origin":<13} {"prior err ms":>13} {"scat med":>9} {"scat p99":>9} {"below":>6} '
            f'{"acc":>3} {"found-prior":>12} {"err ms":>9} reason')
    print(head)
    print('-' * len(head))
    for r in rows:
        fp = '-' if r['found_minus_prior_ms'] is None else f'{r["found_minus_prior_ms"]:+.3f}'
        pe = '-' if r['prior_err_ms'] is None else f'{r["prior_err_ms"]:+.3f}'
        print(f'{(r["rig"] + " " + r["camera"])[:44]:<44} {r["origin"]:<13} {pe:>13} {r["scatter_median_ms"]:>9.3f} '
              f'{r["scatter_p99_ms"]:>9.3f} {r["below_1ms"]:>6.3f} {"yes" if r["accepted"] else "no":>3} {fp:>12} '
              f'{r["error_ms"]:>+9.3f} {r["reason"]}')
    for origin in Origin:
        part = [r for r in rows if r['origin'] == origin.value and r['prior_err_ms'] is not None]
        errs = np.abs([r['prior_err_ms'] for r in part])
        print(f'{origin.value:<13} cameras {len(part):>3}  |prior err| median {np.median(errs):9.3f} ms  max '
              f'{errs.max():10.3f} ms  scatter p99 max {max(r["scatter_p99_ms"] for r in part):8.3f} ms  '
              f'accepted {sum(r["accepted"] for r in part)}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
