"""evsync verify BAG: the density estimate against the trigger edges each camera recorded of one
pulse wired to every camera (docs/triggers.md)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from evsync_ros.bag.edges import CameraEdges, channels_given, read_edges
from evsync_ros.cli import bagopts, tables
from evsync_ros.cli.command import Arguments, Command, Exit, output_file
from evsync_ros.core import lazy
from evsync_ros.core.host import HOST
from evsync_ros.core.latencies import calibrated
from evsync_ros.core.triggers import Verdict, Verified, verify
from evsync_ros.errors import EvsyncError

if TYPE_CHECKING:
    from evsync_ros.bag.estimate import BagEstimate
    from evsync_ros.cli import plots
else:
    plots = lazy.module('evsync_ros.cli.plots')

__all__ = ['COMMAND', 'verified_table']


def declare(a: Arguments) -> None:
    a.add('bag', help='rosbag2 directory (sqlite3 or mcap), a single .db3/.mcap file, or a ROS 1 .bag')
    bagopts.add_selection(a, method_help='refined (default) or paper',
                          latency_help='known envelope latency of a camera in microseconds (taken out of its offset)',
                          host=False)
    a.add('--json', action='store_true', help='print exactly one JSON object: the estimate and each camera verified')
    a.add('--plot', metavar='FILE.png', help="draw each camera's window offsets against its trigger edges")
    a.add('--save-latencies', metavar='FILE',
          help="write each verified camera's envelope latency (density minus triggers, relative to the reference) "
               'for --latencies and the node\'s latencies_file (docs/triggers.md, "Calibrating")')
    bagopts.add_stretch(a, whole='default 0', host=False)  # (the edges are on the cameras' clocks: no host)


def run(args: argparse.Namespace) -> int:
    channels = channels_given(args.trigger_channel)
    output_file(args.plot, option='--plot')
    output_file(args.save_latencies, option='--save-latencies')
    if args.reference == HOST:
        raise EvsyncError('verify: the trigger edges are on the cameras\' clocks; give a camera as --reference')
    est = bagopts.bag_estimate(args, args.bag, edges=False)  # the density's own, to be verified
    rig = est.rig
    unknown = sorted(set(channels) - {c.topic for c in rig.cameras})
    if unknown:
        raise EvsyncError(f'--trigger-channel names {", ".join(unknown)}, which is not a camera of the estimate')
    read = read_edges(args.bag, [c.topic for c in rig.cameras], channels=channels)
    ref = read[rig.reference].edges
    results = [verify(c, ref, read[c.topic].edges, reference=rig.reference) for c in rig.cameras]
    if args.json:
        json.dump({'estimate': rig.as_json(), 'verified': [_entry(v, read[v.topic]) for v in results]}, sys.stdout)
        sys.stdout.write('\n')
    else:
        print(tables.offsets_table(rig, events={t: r.events for t, r in est.reports.items()}) + '\n')
        print(verified_table(results, read))
    say = sys.stderr if args.json else sys.stdout
    if args.plot:
        print(f'wrote {plots.plot_verified(args.plot, rig, results)}', file=say)
    if args.save_latencies:
        _save(args, est, results, say)
    done = all(v.verdict in (Verdict.VERIFIED, Verdict.REFERENCE) and v.within is not False for v in results)
    if len(rig.cameras) == 1:  # the reference alone: nothing verified, as estimate and report say
        print(f'evsync: {bagopts.alone(args.bag, rig.reference)}', file=sys.stderr)
        done = False
    return int(Exit.DONE if done else Exit.INCOMPLETE)


def _save(args: argparse.Namespace, est: BagEstimate, results: list[Verified], say: TextIO) -> None:
    """--save-latencies: what the verified cameras measured, and the rig's light and motion as the
    windows saw them (each camera's events per second over the estimate's span)."""
    if not any(v.verdict is Verdict.VERIFIED for v in results):
        raise EvsyncError(f'{args.bag}: no camera verified against the trigger edges; {args.save_latencies} '
                          'not written')
    start, stop = min(c.window_ns[0] for c in est.rig.cameras), max(c.window_ns[1] for c in est.rig.cameras)
    seconds = max((stop - start) / 1e9, 1e-9)
    seen = {c.topic: {'events': est.reports[c.topic].events,
                      'events_per_s': round(est.reports[c.topic].events / seconds),
                      'windows_agreeing': c.windows_agreeing} for c in est.rig.cameras}
    measured = {'bag': str(Path(args.bag).resolve()), 'method': args.method, 'cameras': seen}
    path = calibrated(results, reference=est.rig.reference, measured=measured).save(args.save_latencies)
    print(f'wrote {path}: latencies relative to {est.rig.reference}', file=say)


def _entry(v: Verified, read: CameraEdges) -> dict[str, object]:
    return {**v.as_json(), 'source': read.source, 'channel': read.channel,
            'channels': {str(k): n for k, n in read.counts.items()}, 'undecodable': read.undecodable}


def verified_table(results: list[Verified], read: dict[str, CameraEdges]) -> str:
    """One line per camera: its edges, the offset they give, the estimate's error against them."""
    head = (f'{"topic":<28} {"edges":>6} {"ch":>3} {"matched":>7} {"trigger offset s":>22} {"error us":>9} '
            f'{"+- us":>7} {"within":>6} {"windows":>7} {"mean us":>8} {"|mean| us":>9} {"max us":>8} {"std us":>7}')
    lines = [head, '-' * len(head)]
    for v in results:
        r = read[v.topic]
        ch = '-' if r.channel is None else str(r.channel)
        if v.verdict is not Verdict.VERIFIED or v.trigger is None:
            lines.append(f'{v.topic:<28} {len(r.edges.t):>6} {ch:>3}  {v.verdict.value}: {v.reason}')
            continue
        s = v.window_stats() or {}
        us = {k: f'{x / 1e3:+.1f}' if k == 'mean_ns' else f'{x / 1e3:.1f}' for k, x in s.items()}
        within = {True: 'yes', False: 'NO', None: '-'}[v.within]
        lines.append(f'{v.topic:<28} {len(r.edges.t):>6} {ch:>3} {v.matched:>7} '
                     f'{tables.format_seconds(v.trigger.offset_ns):>22} {v.error_ns / 1e3:>+9.1f} '  # type: ignore[operator]
                     f'{(v.stated_ns or 0) / 1e3:>7.1f} {within:>6} {len(v.window_errors_ns):>7} '
                     f'{us.get("mean_ns", "-"):>8} {us.get("mean_abs_ns", "-"):>9} {us.get("max_abs_ns", "-"):>8} '
                     f'{us.get("std_ns", "-"):>7}')
    lines.append('error: the density offset minus the edges\' (at the estimate\'s anchor; per window at its middle); '
                 'within: at most 3 of its stated standard errors')
    return '\n'.join(lines)


COMMAND = Command(name='verify', help='check the density estimate against trigger edges wired to every camera',
                  declare=declare, run=run)
