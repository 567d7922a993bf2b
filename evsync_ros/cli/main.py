"""The ``evsync`` command line.

``evsync demo``: the main job on the built-in default: a simulated rig written as a rosbag2, read
back through the adapters, estimated with the paper's method and the refined one; prints estimated
against true offsets.
``evsync estimate BAG``: every event topic's offset (and skew) against a reference, from a rosbag2.
Several bags: each alone in a process of its own (``--jobs``), then a summary (``cli.batch``).
``evsync simulate OUT``: a simulated rig (per-pixel simulator, presets) as a rosbag2 with ground truth.
``evsync restamp BAG OUT``: a copy of a rosbag2 with every event topic on the reference timeline;
``evsync restamp BAG... --output-dir DIR`` (or ``--suffix S``): several, as estimate does.
``evsync report BAG_OR_JSON``: the offsets, their history per window, and plots; a bag's recorded
/evsync/offsets.
``evsync plotjuggler``: a PlotJuggler layout of the node's numeric status topics.
"""

from __future__ import annotations

import argparse
import json
import shutil
import signal
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

import numpy as np

from evsync_ros.bag import pipeline, restamp, ros1
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.writer import ROS1
from evsync_ros.cli import batch, tables
from evsync_ros.cli.argv import positionals_last
from evsync_ros.cli.progress import Progress
from evsync_ros.cli.tables import format_seconds
from evsync_ros.core import lazy
from evsync_ros.core.clock import ClockCorrection, CorrectionTrack
from evsync_ros.core.host import HOST
from evsync_ros.core.results import METHODS, PriorChoice, load_rig
from evsync_ros.errors import EXPECTED_ERRORS, EvsyncError
from msg_adapters.cdr import read_stamp
from msg_adapters.registry import is_event_type

if TYPE_CHECKING:
    from evsync_ros.bag import estimate
    from evsync_ros.cli import plots
    from evsync_ros.core import paper, refined
    from evsync_ros.ros import parameters as config
    from evsync_ros.ros import status
    from evsync_ros.sim import pixelsim, simbag
else:  # what only some commands run, loaded when one does (restamp --offsets runs none of it)
    estimate = lazy.module('evsync_ros.bag.estimate')
    plots = lazy.module('evsync_ros.cli.plots')
    paper = lazy.module('evsync_ros.core.paper')
    refined = lazy.module('evsync_ros.core.refined')
    config = lazy.module('evsync_ros.ros.parameters')
    status = lazy.module('evsync_ros.ros.status')
    pixelsim = lazy.module('evsync_ros.sim.pixelsim')
    simbag = lazy.module('evsync_ros.sim.simbag')

DEMO_IMU_HZ = 200.0
"""The demo's cameras each have an IMU at this rate, restamped with them as companions."""


def _ms(ns: float) -> str:
    return f'{ns / 1e6:+.3f}'


def _latencies(pairs: Sequence[str] | None) -> dict[str, int]:
    """--latency-us TOPIC=US ... as {topic: ns}."""
    out = {}
    for item in pairs or ():
        topic, sep, value = item.rpartition('=')
        try:
            us = float(value)
        except ValueError:
            us = None
        if not sep or not topic or us is None:
            raise EvsyncError(f'--latency-us wants TOPIC=MICROSECONDS, got {item!r}')
        out[topic] = int(round(us * 1000))
    return out


def _companions(pairs: Sequence[str] | None) -> dict[str, str]:
    """--companion TOPIC=EVENT_TOPIC ... as {topic: event topic}."""
    out: dict[str, str] = {}
    for item in pairs or ():
        topic, sep, camera = item.partition('=')
        if not sep or not topic.startswith('/') or not camera.startswith('/'):
            raise EvsyncError(f'--companion wants TOPIC=EVENT_TOPIC (both absolute names), got {item!r}')
        if topic in out and out[topic] != camera:
            raise EvsyncError(f'--companion {topic} given two cameras: {out[topic]} and {camera}')
        out[topic] = camera
    return out


def _paper_params(args: argparse.Namespace) -> paper.PaperParams:
    values = config.load_ros_parameters(args.params_file, rcl=True) if args.params_file else {}
    for key in config.PAPER_KEYS:
        if getattr(args, key) is not None:
            values[key] = getattr(args, key)
    return config.paper_params_from(values, source=args.params_file or 'command line')


def _demo(args: argparse.Namespace) -> int:
    """The whole path on a simulated rig: bag, estimate (both methods), restamp, report; against truth."""
    params = _paper_params(args)
    rig = pixelsim.preset(args.preset, seed=args.seed, duration_s=args.duration)
    workdir = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix='evsync-demo-'))
    try:
        if args.keep:
            workdir.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        events = pixelsim.simulate(rig, imu_hz=DEMO_IMU_HZ)
        bag = workdir / f'{args.preset}-seed{args.seed}'
        truth = simbag.write_rig(rig, events, bag)
        companions = {c['imu_topic']: c['topic'] for c in truth['cameras']}
        t_sim = time.perf_counter() - t0
        t0 = time.perf_counter()
        fits = {m: estimate.estimate_bag(bag, reference=rig.reference, method=m, paper_params=params)
                for m in ('paper', 'refined')}
        t_est = time.perf_counter() - t0
        refined = fits['refined']
        restamped = workdir / f'{bag.name}-restamped'
        t0 = time.perf_counter()
        restamp.restamp_bag(bag, restamped, corrections=refined.rig.corrections,
                            reference=rig.reference, companions=companions)
        t_restamp = time.perf_counter() - t0
        after = estimate.estimate_bag(restamped, reference=rig.reference)
        plot = plots.plot(args.plot, refined.rig, windows=refined.windows, binned=_binned(refined),
                           title=f'evsync demo: {args.preset}, seed {args.seed}') if args.plot else None
        times, _ = estimate.read_event_times(bag)  # one pass: where each camera's middle event sits
        middles = {t: int(np.median(arr)) for t, arr in times.items()}
        del times
        imu_errors = _companion_errors(bag, restamped, companions, truth)
    finally:
        if not args.keep:
            shutil.rmtree(workdir, ignore_errors=True)
    rows = []
    for cam in truth['cameras']:
        mid = middles[cam['topic']]
        row = {'topic': cam['topic'], 'encoding': cam['encoding'], 'events': cam['events'], 'truth': cam}
        for m, fit in fits.items():
            est = next(c for c in fit.rig.cameras if c.topic == cam['topic'])
            row[m] = {**est.as_json(), 'error_ns': simbag.error_ns(est.as_json(), cam, mid)}
        row['after_restamp_ns'] = next(c for c in after.rig.cameras if c.topic == cam['topic']).offset_ns
        row['imu_topic'] = cam['imu_topic']
        row['imu_error_ns'] = imu_errors[cam['imu_topic']]
        rows.append(row)
    if args.json:
        json.dump({'preset': args.preset, 'seed': args.seed, 'reference': rig.reference, 'cameras': rows,
                   'plot': str(plot) if plot else None}, sys.stdout, indent=2)
        sys.stdout.write('\n')
        return 0
    print(f'Simulated rig "{args.preset}" (seed {args.seed}): {pixelsim.PRESETS[args.preset]}')
    print(f'{len(rig.cameras)} cameras, {args.duration:g} s, {sum(r["events"] for r in rows):,} events; '
          f'simulated and written as a rosbag2 in {t_sim:.1f} s' + (f' ({bag})' if args.keep else ''))
    print(f'Paper method: tau {params.tau_ns / 1e6:g} ms, T {params.window_ns / 1e9:g} s, '
          f'epsilon {params.epsilon:g}, p{params.percentile:g}, min overlap {params.min_overlap:g}. '
          f'Refined: windows that must agree, each refined to microseconds with its standard error; drift.')
    print(f'Both estimated from the bag in {t_est:.2f} s; restamped with the refined estimate in {t_restamp:.2f} s'
          + (f' ({restamped})' if args.keep else '') + f'; reference {rig.reference}')
    print('Errors are at the middle of each camera\'s recording; "after restamp" is the refined estimate '
          'on the restamped bag\n')
    head = (f'{"camera":<20} {"type":<6} {"events":>9} {"true offset s":>22} {"paper err ms":>12} '
            f'{"refined err ms":>14} {"+- ms":>6} {"windows":>7} {"skew ppm (true)":>16} {"after restamp ms":>16}')
    print(head)
    print('-' * len(head))
    for r in rows:
        p, f, t = r['paper'], r['refined'], r['truth']
        print(f'{r["topic"]:<20} {r["encoding"]:<6} {r["events"]:>9,} {format_seconds(t["offset_ns"]):>22} '
              f'{_ms(p["error_ns"]):>10}{"" if p["accepted"] else " X":<2} {_ms(f["error_ns"]):>12}'
              f'{"" if f["accepted"] else " X":<2} {_se_ms(f):>6} {_windows(f, r["topic"] == rig.reference):>7} '
              f'{f["skew_ppm"]:>+7.1f} ({t["skew_ppm"]:>+6.1f}) {_ms(r["after_restamp_ns"]):>16}')
    print('\nX: not accepted. +- ms: the refined offset\'s standard error; windows: how many of the camera\'s '
          'windows agree.\nThe paper reports 1.4-4.6 ms mean, 9.4 ms max error on real rigs.')
    print(f'Each camera\'s IMU ({DEMO_IMU_HZ:g} Hz, on the camera\'s clock) was restamped with it as a companion; '
          'worst IMU stamp against the truth, ms: '
          + ', '.join(f'{r["imu_topic"]} {_ms(r["imu_error_ns"])}' for r in rows))
    if plot:
        print(f'Plots (densities before and after, D(dt), offset over time): {plot}')
    return 0


def _companion_errors(bag: Path, restamped: Path, companions: Mapping[str, str],
                      truth: Mapping[str, Any]) -> dict[str, int]:
    """Per companion topic, the worst distance of a restamped header.stamp from where its camera's
    truth puts the original one."""
    cams = {c['topic']: c for c in truth['cameras']}
    stamps: dict[str, list[list[int]]] = {t: [[], []] for t in companions}
    for k, path in enumerate((bag, restamped)):
        with BagReader(path) as reader:
            for conn, _, raw in reader.messages(list(companions)):
                stamps[conn.topic][k].append(read_stamp(raw))
    out = {}
    for topic, (before, after) in stamps.items():
        c = cams[companions[topic]]
        true_map = ClockCorrection(offset_ns=c['offset_ns'], skew_ppm=c['skew_ppm'], anchor_ns=c['anchor_ns'])
        out[topic] = max((abs(a - true_map.apply_one(b)) for b, a in zip(before, after)), default=0)
    return out


def _simulate(args: argparse.Namespace) -> int:
    rig = pixelsim.preset(args.preset, seed=args.seed, duration_s=args.duration, speed_px_s=args.speed,
                          make=pixelsim.parse_make(args.make) if args.make else None, triggers_hz=args.triggers)
    storage = ROS1 if ros1.is_ros1(args.out) else args.storage
    truth = simbag.write_rig(rig, pixelsim.simulate(rig, imu_hz=args.imu_hz), args.out, storage=storage,
                             truth=args.truth)
    for cam in truth['cameras']:
        print(f'{cam["topic"]:<20} {cam["encoding"]:<5} {cam["events"]:>10,} events  '
              f'offset {format_seconds(cam["offset_ns"])} s  '
              f'skew {cam["skew_ppm"]:+.2f} ppm')
    print(f'wrote {args.out} and {args.truth or args.out + ".truth.json"}')
    return 0


def _warn_reading(reports: Mapping[str, estimate.TopicReport], late: Mapping[str, int] | None = None,
                  far: Mapping[str, int] | None = None) -> None:
    for topic, rep in reports.items():
        if rep.undecodable:
            print(f'evsync: {topic}: {rep.undecodable} of {rep.messages} messages could not be decoded '
                  f'(first: {rep.first_error})', file=sys.stderr)
        if rep.anomalies:
            print(f'evsync: {topic}: counted while decoding: '
                  + ', '.join(f'{k} x{v}' for k, v in sorted(rep.anomalies.items())), file=sys.stderr)
    for topic, n in (late or {}).items():
        print(f'evsync: {topic}: {n} events came too far out of order for their window and were not used',
              file=sys.stderr)
    for topic, n in (far or {}).items():
        print(f'evsync: {topic}: {n} events lie over a minute from the rest of their message (corrupt times) '
              'and were not used', file=sys.stderr)


def _stream_reference(args: argparse.Namespace, tracked: list[str]) -> str:
    """The reference of a recorded offsets stream: --reference, else the one event topic of the input
    with no recorded correction (the node publishes none for its reference), else host when every
    camera has them."""
    if args.reference:
        return str(args.reference)
    with BagReader(args.bag) as reader:
        events = [c.topic for c in reader.connections if is_event_type(c.msgtype)]
    untracked = [t for t in events if t not in tracked]
    if len(untracked) == 1:
        return untracked[0]
    if not untracked:
        return 'host'
    raise EvsyncError(f'{args.offsets}: the offsets name {", ".join(tracked) or "no camera"}; the event topics '
                      f'{", ".join(untracked)} have none, so which is the reference? Give --reference')


def _made(record: Mapping[str, Any]) -> str:
    """How a restamped bag was made, in a line (its provenance)."""
    how = f"--offsets {record['offsets_file']}" if 'offsets_file' in record else f"method {record.get('method', '?')}"
    return (f"evsync {record.get('evsync_version', '?')} at {record.get('written_utc', '?')}, from "
            f"{record.get('input', '?')}, {how}, reference {record.get('reference', '?')}")


def _stretch(args: argparse.Namespace) -> str:
    """', from 5 s for 10 s' of --start and --duration ('' for the whole bag)."""
    if args.start is None and args.duration is None:
        return ''
    return f', from {args.start or 0:g} s' + (f' for {args.duration:g} s' if args.duration is not None else ' on')


def _bag_estimate(args: argparse.Namespace, bag: str, label: str = 'estimating', *,
                  consistency: bool = False) -> estimate.BagEstimate:
    bar = Progress(f'{label} {Path(bag).name}')
    try:
        if args.host_latency_us is not None and args.reference != 'host':
            raise EvsyncError('--host-latency-us is for --reference host')
        floor = round((args.host_latency_us or 0.0) * 1000)
        est = estimate.estimate_bag(bag, topics=args.topics, reference=args.reference, method=args.method,
                                    latencies_ns=_latencies(args.latency_us), host_floor_ns=floor, progress=bar,
                                    start_s=args.start, duration_s=args.duration, consistency=consistency,
                                    parallel=pipeline.available(jobs=getattr(args, 'jobs', 1)), prior=args.prior)
    finally:
        bar.close()
    _warn_reading(est.reports, est.late_events, est.far_events)
    return est


def _alone(bag: str, topic: str) -> str:
    """What is said of a bag with one event camera (and a camera, not the host, for reference)."""
    return (f'{bag}: one event topic, {topic}: nothing to synchronise it with (a bag of two cameras or more '
            'is; --reference host puts one camera on the host\'s clock)')


def _estimate(args: argparse.Namespace) -> int:
    """``evsync estimate BAG``, or several bags (``_many``)."""
    if len(args.bag) > 1:
        return _many(args, [batch.Plan(bag) for bag in args.bag])
    args.bag = args.bag[0]
    return _estimate_one(args).status


def _estimate_one(args: argparse.Namespace) -> batch.Ran:
    t0 = time.perf_counter()
    est = _bag_estimate(args, args.bag, consistency=args.consistency)
    rig, reports = est.rig, est.reports
    elapsed = time.perf_counter() - t0
    alone = len(rig.cameras) == 1 and rig.reference != HOST
    if alone:  # the estimate (the reference alone) is printed as asked; the exit status says it did nothing
        print(f'evsync: {_alone(args.bag, rig.reference)}', file=sys.stderr)
    status = 0 if all(c.accepted for c in rig.cameras) and not alone else 1
    ran = batch.Ran(status=status, accepted=sum(c.accepted for c in rig.cameras), cameras=len(rig.cameras),
                    estimate=rig.as_json())
    if args.json:
        json.dump(rig.as_json(), sys.stdout)
        sys.stdout.write('\n')
        return ran
    print(f'{args.bag}: method {args.method}{_stretch(args)}, estimated in {elapsed:.2f} s\n')
    print(tables.offsets_table(rig, events={t: r.events for t, r in reports.items()}))
    if rig.pair_residual_ns:
        worst = max(rig.pair_residual_ns.items(), key=lambda kv: abs(kv[1]))
        print(f'\nconsistency over {len(rig.pair_residual_ns)} camera pairs: largest disagreement '
              f'{_ms(worst[1])} ms ({worst[0][0]} vs {worst[0][1]})')
    elif args.consistency and args.method == 'refined':
        first = (est.timeline or rig).reference  # with reference host: the cameras were on this one's timeline
        others = sum(c.accepted for c in rig.cameras if c.topic != first)
        print(f'\nconsistency: no camera pair to check ({others} accepted camera(s) besides the reference; a pair '
              f'needs two, and its own estimate accepted)')
    elif args.consistency:
        print('\nconsistency: the pairs are checked with the refined method only')
    return ran


def _restamp(args: argparse.Namespace) -> int:
    """``evsync restamp BAG OUT``, or several bags into ``--output-dir`` or beside themselves with
    ``--suffix`` (``_many``)."""
    if args.output_dir is None and args.suffix is None:
        if len(args.bag) != 2:
            raise EvsyncError(f'restamp takes BAG OUT, or several bags with --output-dir DIR or --suffix S '
                              f'(got {len(args.bag)} path(s): {" ".join(args.bag)})')
        if args.json:
            raise EvsyncError('restamp --json gives the summary of several bags: name their outputs with '
                              '--output-dir DIR or --suffix S (restamp BAG OUT prints its tables)')
        args.bag, args.out = args.bag
        return _restamp_one(args).status
    plans = batch.outputs(args.bag, directory=args.output_dir, suffix=args.suffix or '')
    if args.output_dir is not None:
        Path(args.output_dir).mkdir(parents=True, exist_ok=True)
    return _many(args, plans, restamp=True)


def _many(args: argparse.Namespace, plans: Sequence[batch.Plan], *, restamp: bool = False) -> int:
    """Each bag in its own process, ``--jobs`` at once; the summary (a table, or with ``--json`` one
    object) and the exit status of them all (``batch.exit_status``)."""
    relay = batch.Relay.INHERIT if args.jobs == 1 else batch.Relay.PREFIX
    runs = batch.run_bags(plans, args, jobs=args.jobs, relay=relay, quiet=args.json)
    if args.json:
        json.dump(batch.summary_json(runs), sys.stdout)
        sys.stdout.write('\n')
    else:
        print(f'\n{len(runs)} bags, {args.jobs} at a time\n' + batch.summary_table(runs, restamp=restamp))
    return batch.exit_status(runs)


def _restamp_one(args: argparse.Namespace) -> batch.Ran:
    if Path(args.out).exists():
        raise EvsyncError(f'{args.out}: exists already; refusing to overwrite it')
    companions = _companions(args.companion)
    if not args.offsets and args.reference != HOST:
        with BagReader(args.bag) as reader:
            events = sorted({c.topic for c in reader.connections if is_event_type(c.msgtype)
                             and (not args.topics or c.topic in args.topics)})
        if len(events) == 1:  # a copy would change nothing: an error, before anything is read or written
            raise EvsyncError(f'{_alone(args.bag, events[0])}; nothing written')
    rig = None
    if args.offsets:
        if args.start is not None or args.duration is not None:
            raise EvsyncError('--start and --duration choose the stretch to estimate from; with --offsets '
                              'nothing is estimated (the whole bag is restamped either way)')
        tracks: dict[str, CorrectionTrack] = {}
        if Path(args.offsets).suffix == '.json':
            reference, corrections = restamp.load_offsets(args.offsets)
            provenance: dict[str, Any] = {'offsets_file': str(Path(args.offsets).resolve()),
                                          'estimate': json.loads(Path(args.offsets).read_text())}
        else:
            tracks = restamp.load_offsets_stream(args.offsets, topic=args.offsets_topic)
            reference, corrections = _stream_reference(args, sorted(tracks)), {}
            provenance = {'offsets_file': str(Path(args.offsets).resolve()), 'offsets_topic': args.offsets_topic}
            for topic, track in tracks.items():
                print(f'{topic}: {len(track)} corrections recorded on {args.offsets_topic}')
        if args.topics:
            corrections = {t: c for t, c in corrections.items() if t in args.topics or t == reference}
            tracks = {t: c for t, c in tracks.items() if t in args.topics}
        print(f'offsets from {args.offsets} (reference {reference})')
    else:
        tracks = {}
        est = _bag_estimate(args, args.bag)
        print(tables.offsets_table(est.rig, events={t: r.events for t, r in est.reports.items()}))
        refused = [c.topic for c in est.rig.cameras if not c.accepted]
        if refused and not args.force:
            raise EvsyncError(f'no accepted estimate for {", ".join(refused)}; nothing written '
                              '(--force restamps with the best rejected estimate)')
        corrections = est.rig.corrections
        reference = est.rig.reference
        rig = est.rig
        provenance = {'method': args.method, 'estimate': est.rig.as_json(), 'forced': bool(refused)}
        if args.start is not None or args.duration is not None:
            provenance['estimated_from_s'] = {'start': args.start or 0.0, 'duration': args.duration}
    bar = Progress(f'restamping into {Path(args.out).name}')
    t0 = time.perf_counter()
    try:
        rep = restamp.restamp_bag(args.bag, args.out, corrections=corrections, reference=reference,
                                  storage=args.storage, companions=companions,
                                  record_time=args.record_time, progress=bar, provenance=provenance, tracks=tracks,
                                  parallel=pipeline.available(jobs=getattr(args, 'jobs', 1)))
    finally:
        bar.close()
    elapsed = time.perf_counter() - t0
    if rep.previous is not None:
        print(f'evsync: warning: {args.bag} was restamped by evsync already ({_made(rep.previous)}): these '
              'corrections were applied on top of those', file=sys.stderr)
    for stale in rep.stale_removed:
        print(f'evsync: removed {stale}, the partial output of a run that was killed', file=sys.stderr)
    print(f'\nwrote {rep.output} ({rep.storage}) in {elapsed:.1f} s; '
          + ('what was applied is in its metadata (evsync report shows it)' if rep.provenance is not None else
             'a ROS 1 bag has no metadata to record what was applied in'))
    head = f'{"topic":<28} {"type":<36} {"messages":>9} {"restamped":>9}  record timestamps'
    print(head)
    print('-' * len(head))
    for topic, t in rep.topics.items():
        record = {None: 'as recorded', True: 'moved with header.stamp',
                  False: 'kept (a header not on the recorder\'s clock)'}
        print(f'{topic:<28} {t.msgtype:<36} {t.messages_out:>9,} {t.restamped:>9,}  {record[t.record_shifted]}')
    for topic, t in rep.topics.items():
        if t.unconvertible:
            print(f'evsync: {topic}: {t.unconvertible} ROS 1 messages do not match their definition and have no '
                  f'ROS 2 form: not written (first: {t.first_error}); write a .bag output to keep them',
                  file=sys.stderr)
        if t.unchanged_bad:
            print(f'evsync: {topic}: {t.unchanged_bad} messages could not be restamped and were written unchanged '
                  f'(first: {t.first_error})', file=sys.stderr)
        if t.stamps is not None and t.stamps.disagreeing:
            print(f'evsync: warning: {t.stamps.says()}', file=sys.stderr)
    return batch.Ran(status=1 if rep.bad else 0, output=str(rep.output),
                     accepted=None if rig is None else sum(c.accepted for c in rig.cameras),
                     cameras=None if rig is None else len(rig.cameras), estimate=None if rig is None else rig.as_json())


def _report(args: argparse.Namespace) -> int:
    src = Path(args.source)
    if src.is_file() and src.suffix == '.json':
        if args.start is not None or args.duration is not None:
            raise EvsyncError(f'{src}: --start and --duration are for bags, not an estimate JSON')
        rig = load_rig(src)
        print(tables.offsets_table(rig))
        if args.plot:
            print(f'wrote {plots.plot(args.plot, rig, title=str(src))}')
        return 0
    with BagReader(src) as reader:
        made = reader.provenance
        recorded = any(c.topic == args.offsets_topic for c in reader.connections)
        events = any(is_event_type(c.msgtype) for c in reader.connections)
    if made is not None:
        print(f'{args.source} was restamped by evsync: {_made(made)}')
        print(tables.provenance_table(made) + '\n')
    if recorded:  # what evsync_node knew as the bag was recorded (its offsets topic recorded with the rig)
        tracks = restamp.load_offsets_stream(src, topic=args.offsets_topic)
        print(tables.recorded_offsets_table(tracks, topic=args.offsets_topic) + '\n')
        if args.plot:
            drawn = plots.plot_recorded(_recorded_plot(args.plot) if events else args.plot, tracks,
                                        title=f'{args.source}: {args.offsets_topic}')
            print(f'wrote {drawn}\n')
        if not events:
            return 0
    elif not events:
        raise EvsyncError(f'{src}: no event topic to estimate from, and no {args.offsets_topic} recorded to show')
    est = _bag_estimate(args, args.source)
    params = refined.RefinedParams()
    print(f'{args.source}: method {args.method}{_stretch(args)}, {est.passes} pass(es) over the bag, '
          f'at most {est.peak_bin_bytes / 1e6:.1f} MB of binned counts held\n')
    print(tables.offsets_table(est.rig, events={t: r.events for t, r in est.reports.items()}))
    if est.windows:
        print()
        print(tables.history_table((est.timeline or est.rig).cameras, est.windows, binned=_binned(est)))
    if args.plot:
        if not est.windows:
            raise EvsyncError('plots are drawn from the refined method\'s windows; use --method refined')
        drawn = plots.plot(args.plot, est.timeline or est.rig, windows=est.windows, tau_ns=params.tau_ns,
                           title=str(args.source), binned=_binned(est))
        print(f'\nwrote {drawn}')
    return 0 if all(c.accepted for c in est.rig.cameras) else 1


def _binned(est: estimate.BagEstimate) -> Mapping[str, ClockCorrection]:
    """The correction each camera's kept windows were binned through (``BagEstimate.binned``: a
    de-skewed pass's windows are offsets on the de-skewed timeline)."""
    return est.binned


def _plotjuggler(args: argparse.Namespace) -> int:
    values = config.node_defaults()
    if args.params_file:
        values.update(config.load_ros_parameters(args.params_file, rcl=True))
    topics = args.topics or values['topics']
    status_topic = values['status_topic'] if args.status_topic is None else args.status_topic
    if not status_topic.startswith('/') or not all(t.startswith('/') for t in topics):
        raise EvsyncError(f'the status topic and the event topics must be absolute names, got {status_topic!r} and '
                          f'{list(topics)}')
    text = status.layout(list(topics), status_topic=status_topic)
    if not args.output:
        print(text, end='')
        return 0
    try:
        with open(args.output, 'x', encoding='utf-8') as f:
            f.write(text)
    except FileExistsError as exc:
        raise EvsyncError(f'{args.output} exists; the layout is not written over it') from exc
    print(f'wrote {args.output}: {len(topics)} cameras under {status_topic}', file=sys.stderr)
    return 0


def _recorded_plot(plot: str) -> Path:
    """Where ``report --plot FILE.png`` draws a bag's recorded offsets when the estimate's figure takes
    FILE.png: FILE-offsets.png."""
    p = Path(plot)
    return p.with_name(f'{p.stem}-offsets{p.suffix or ".png"}')


def _se_ms(cam: dict[str, Any]) -> str:
    se = cam.get('uncertainty_ns')
    return f'{se / 1e6:.3f}' if isinstance(se, (int, float)) and se > 0 else '-'


def _windows(cam: dict[str, Any], reference: bool) -> str:
    return '-' if reference else f'{cam["windows_agreeing"]}/{cam["windows_total"]}'


def _jobs(text: str) -> int:
    """--jobs N: a whole number, 1 or more."""
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f'wants a whole number of processes, 1 or more, got {text!r}')
    return n


def build_parser() -> argparse.ArgumentParser:
    """The ``evsync`` argument parser, every command and option (``evsync play`` has its own)."""
    parser = argparse.ArgumentParser(prog='evsync', description=__doc__.split('\n\n')[0])
    sub = parser.add_subparsers(dest='command', required=True)
    demo = sub.add_parser('demo', help='simulate a rig with known offsets, estimate them with both methods')
    demo.add_argument('--preset', choices=pixelsim.PRESETS, default='mixed-models',
                      help='kind of rig and scene (default mixed-models)')
    demo.add_argument('--seed', type=int, default=0, help='simulation seed (default 0)')
    demo.add_argument('--duration', type=float, default=20.0, help='seconds of world time (default 20)')
    demo.add_argument('--keep', metavar='DIR', help='keep the simulated bag and its truth JSON in DIR')
    demo.add_argument('--params-file', help='ROS 2 parameter YAML (node evsync) for the paper method')
    demo.add_argument('--tau-ms', type=float, help='paper method: bin width tau in ms (default 1)')
    demo.add_argument('--window-s', type=float, help='paper method: window T in s (default 10)')
    demo.add_argument('--epsilon', type=float, help='paper method: acceptance threshold (default 1e-4)')
    demo.add_argument('--percentile', type=float, help='paper method: search-range percentile (default 50)')
    demo.add_argument('--min-overlap', type=float, help='paper method: least overlap of a shift (default 0.5)')
    demo.add_argument('--plot', default='evsync-demo.png', metavar='FILE.png',
                      help="where to draw the refined estimate's plots (default evsync-demo.png; '' for none)")
    demo.add_argument('--json', action='store_true', help='print one JSON object instead of the table')
    demo.set_defaults(func=_demo)
    sim = sub.add_parser('simulate', help='simulate a rig into a rosbag2 with a ground-truth JSON beside it')
    sim.add_argument('out', help='bag directory to create (must not exist); a name ending in .bag: a ROS 1 bag')
    sim.add_argument('--preset', choices=pixelsim.PRESETS, default='mixed-models')
    sim.add_argument('--seed', type=int, default=0)
    sim.add_argument('--duration', type=float, help='seconds of world time (default 30; 60 for drift)')
    sim.add_argument('--storage', choices=('sqlite3', 'mcap'), default='sqlite3',
                     help='rosbag2 storage (default sqlite3)')
    sim.add_argument('--truth', help='ground-truth JSON path (default OUT.truth.json)')
    sim.add_argument('--imu-hz', type=float, default=0.0,
                     help="also each camera's IMU at this rate, on <namespace>/imu (default 0: none)")
    sim.add_argument('--speed', type=float, metavar='PX_S',
                     help="typical edge speed in the reference camera's pixels per second (default: the preset's)")
    sim.add_argument('--make', metavar='KEY=VALUE,...',
                     help='every camera but the reference of another make: contrast, lowpass-us, refractory-us, '
                          'noise-hz (e.g. contrast=0.30,lowpass-us=800)')
    sim.add_argument('--triggers', type=float, default=0.0, metavar='HZ',
                     help='a pulse train at HZ wired to every camera\'s trigger input (default 0: none)')
    sim.set_defaults(func=_simulate)
    est = sub.add_parser('estimate', help='estimate every event topic\'s offset and skew in a rosbag2')
    est.add_argument('bag', nargs='+', metavar='BAG',
                     help='rosbag2 directory (sqlite3 or mcap), a single .db3/.mcap file, or a ROS 1 .bag; several: '
                          'each estimated alone, then a summary (--jobs)')
    est.add_argument('--topics', nargs='+', help='event topics to use (default: every event topic)')
    est.add_argument('--reference', help='reference topic (default: the first of --topics, else the first by name), '
                                         "or 'host': every camera onto host (ROS) time")
    est.add_argument('--method', choices=METHODS, default='refined',
                     help='refined (default) or paper (the paper, faithfully)')
    est.add_argument('--latency-us', nargs='+', metavar='TOPIC=US',
                     help='known envelope latency of a camera in microseconds (taken out of its offset; see README)')
    est.add_argument('--json', action='store_true',
                     help='print exactly one JSON object (the estimate contract; several bags: {"bags": [...]}, '
                          'one entry per bag)')
    est.add_argument('--consistency', action='store_true',
                     help='also estimate every camera pair and print the largest disagreement '
                          '(holds all events in memory)')
    est.set_defaults(func=_estimate, one=_estimate_one)
    rs = sub.add_parser('restamp', help='write a copy of a rosbag2 with every event topic on the reference timeline',
                        usage='evsync restamp [options] BAG OUT\n       evsync restamp [options] BAG [BAG ...] '
                              '(--output-dir DIR | --suffix S) [--jobs N] [--json]')
    rs.add_argument('bag', nargs='+', metavar='BAG',
                    help='BAG OUT: the input rosbag2 or ROS 1 .bag (only read) and the output bag directory (must not '
                         'exist; a name ending in .bag: a ROS 1 bag). With --output-dir or --suffix: every path is an '
                         'input, each restamped alone, then a summary (--jobs)')
    rs.add_argument('--output-dir', metavar='DIR',
                    help='several bags: write each into DIR (created if missing) under its own name (with --suffix)')
    rs.add_argument('--json', action='store_true',
                    help='with --output-dir or --suffix: print one JSON object, {"bags": [...]}, one entry per bag '
                         '(instead of the tables)')
    rs.add_argument('--suffix', metavar='S',
                    help="several bags: each output's name is its input's with S added (before .bag); beside its "
                         'input unless --output-dir')
    rs.add_argument('--offsets', metavar='FILE.json|BAG',
                    help='use the offsets of `evsync estimate --json` instead of estimating, or a bag\'s recorded '
                         '/evsync/offsets (what evsync_node knew as it ran, drift included; the input itself when '
                         'it was recorded with them)')
    rs.add_argument('--offsets-topic', default=restamp.OFFSETS_TOPIC, metavar='TOPIC',
                    help='with --offsets BAG: the node\'s offsets topic (default /evsync/offsets)')
    rs.add_argument('--storage', choices=('sqlite3', 'mcap'),
                    help='rosbag2 output storage (default: the input\'s; mcap for a ROS 1 input)')
    rs.add_argument('--record-time', choices=restamp.RECORD_TIME, default='auto',
                    help='record timestamps of restamped topics: moved with header.stamp, kept, or auto (default: '
                         'moved when the header is stamped with the recorder\'s clock)')
    rs.add_argument('--companion', action='append', metavar='TOPIC=EVENT_TOPIC',
                    help="a topic on an event camera's clock (its IMU, frames, camera_info: any type beginning "
                         "with a std_msgs/Header), restamped with that camera's correction, header.stamp only "
                         '(repeatable)')
    rs.add_argument('--force', action='store_true', help='restamp even cameras whose estimate was not accepted')
    rs.set_defaults(func=_restamp, one=_restamp_one)
    rp = sub.add_parser('report', help='offsets table, offset history and plots from a rosbag2 or an estimate JSON')
    rp.add_argument('source', help='a rosbag2, a ROS 1 .bag, or the JSON of `evsync estimate --json`')
    rp.add_argument('--plot', metavar='FILE.png',
                    help="draw densities, D(dt) and offset over time (a bag's recorded offsets: FILE-offsets.png, "
                         'or FILE.png when it holds no event topic)')
    rp.add_argument('--offsets-topic', default=restamp.OFFSETS_TOPIC, metavar='TOPIC',
                    help="the node's offsets topic: when the bag recorded it, what the node published on it is "
                         'shown first, and is all that is shown of a bag without event topics (default '
                         '/evsync/offsets)')
    rp.set_defaults(func=_report)
    for p in (est, rs):
        p.add_argument('-j', '--jobs', type=_jobs, default=1, metavar='N',
                       help='several bags: how many at once, each in a process of its own (default 1)')
    for p in (est, rs, rp):
        what = 'the whole bag is restamped' if p is rs else 'default 0'
        p.add_argument('--start', type=float, metavar='S',
                       help=f"estimate from the messages recorded from S seconds after the bag's first ({what})")
        p.add_argument('--duration', type=float, metavar='S',
                       help='estimate from S seconds of the bag from --start on (default: to its end)')
        p.add_argument('--host-latency-us', type=float, metavar='US',
                       help='with --reference host: the least latency from an event to the host, if known '
                            '(taken out; else host times are late by it)')
        p.add_argument('--prior', choices=[c.value for c in PriorChoice], default=PriorChoice.AUTO.value,
                       help="what places each camera's windows: auto (default: its record times where they behave "
                            "as one clock's arrivals, else its events alone), arrival, or events")
        if p is not est:
            p.add_argument('--topics', nargs='+', help='event topics to use (default: every event topic)')
            p.add_argument('--reference',
                           help='reference topic (default: the first of --topics, else the first by name), '
                                "or 'host': every camera onto host (ROS) time")
            p.add_argument('--method', choices=METHODS, default='refined', help='refined (default) or paper')
            p.add_argument('--latency-us', nargs='+', metavar='TOPIC=US', help='known envelope latency of a camera')
    pj = sub.add_parser('plotjuggler', help="write a PlotJuggler layout of evsync_node's numeric status topics "
                                            '(offset, its standard error, skew, state per camera)')
    pj.add_argument('--params-file', help="the node's parameter YAML: its topics and status_topic (default: the "
                                          'shipped config/evsync.yaml)')
    pj.add_argument('--topics', nargs='+', help="event topics (instead of the parameter file's)")
    pj.add_argument('--status-topic', help="the node's status_topic (instead of the parameter file's)")
    pj.add_argument('-o', '--output', metavar='FILE.xml', help='layout to write (must not exist; default: standard '
                                                               'output); open it with plotjuggler --layout FILE.xml')
    pj.set_defaults(func=_plotjuggler)
    sub.add_parser('play', add_help=False,
                   help='publish a rosbag2 over ROS at its recorded pace (needs rclpy; evsync play --help)')
    return parser


INTERNAL_ERROR = 70
"""The exit status of a command that met a defect of evsync_ros (sysexits' EX_SOFTWARE)."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run one ``evsync`` command; the exit status: 0 done, 1 done with something not accepted or
    messages written unchanged, 2 a clear error (its message on standard error), 130 interrupted,
    ``INTERNAL_ERROR`` a defect of evsync_ros (its traceback on standard error)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ['play']:  # an rclpy front end: imported only when asked for
        from evsync_ros.cli.play import main as play_main
        return play_main(argv[1:])
    parser = build_parser()
    args = parser.parse_args(_positionals_first(parser, argv))
    main_thread = threading.current_thread() is threading.main_thread()
    if main_thread:
        previous = signal.signal(signal.SIGTERM, _terminated)  # unwind (partial outputs removed), not vanish
    try:
        return int(args.func(args))
    except EXPECTED_ERRORS as exc:
        print(f'evsync: error: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('evsync: interrupted; nothing partial was left behind', file=sys.stderr)
        return 130
    except Exception:  # noqa: BLE001 (a defect: Python's own status for it, 1, would read as "not accepted")
        traceback.print_exc()
        print('evsync: internal error: a defect of evsync_ros, not of the input (please report it with the '
              'traceback above)', file=sys.stderr)
        return INTERNAL_ERROR
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)


def _positionals_first(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """A command's options before or after its bag: ``evsync estimate --topics /a /b BAG`` as
    ``evsync estimate BAG --topics /a /b`` (``argv.positionals_last``)."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    if argv and argv[0] in sub.choices:
        return [argv[0], *positionals_last(sub.choices[argv[0]], argv[1:], least=_least(argv))]
    return argv


def _least(argv: Sequence[str]) -> int | None:
    """The fewest positionals of a command line: restamp's BAG OUT, unless its outputs are named by
    --output-dir or --suffix (then one bag or more, as the parser says)."""
    if argv[0] != 'restamp':
        return None
    named = any(a.split('=', 1)[0] in ('--output-dir', '--suffix') for a in argv[1:])
    return None if named else 2


def _terminated(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


if __name__ == '__main__':
    sys.exit(main())
