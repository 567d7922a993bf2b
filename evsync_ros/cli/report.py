"""evsync report BAG_OR_JSON: the offsets, their history per window, and plots; a bag's recorded
/evsync/offsets and how a restamped bag was made."""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from evsync_ros.bag import restamp
from evsync_ros.bag.reader import BagReader
from evsync_ros.cli import bagopts, tables
from evsync_ros.cli.command import Arguments, Command, Exit, output_file
from evsync_ros.cli.estimate import status_of
from evsync_ros.core import lazy
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.results import Method, load_rig
from evsync_ros.errors import EvsyncError
from msg_adapters.registry import is_event_type

if TYPE_CHECKING:
    from evsync_ros.bag import estimate
    from evsync_ros.cli import plots
    from evsync_ros.core import refined
else:  # what only some reports draw or fit, loaded when one does
    plots = lazy.module('evsync_ros.cli.plots')
    refined = lazy.module('evsync_ros.core.refined')

__all__ = ['COMMAND']


def declare(a: Arguments) -> None:
    a.add('source', help='a rosbag2, a ROS 1 .bag, or the JSON of evsync estimate --json')
    a.add('--plot', metavar='FILE.png',
          help="draw densities, D(dt) and offset over time (a bag's recorded offsets: FILE-offsets.png, "
               'or FILE.png when it holds no event topic)')
    a.add('--offsets-topic', default=restamp.OFFSETS_TOPIC, metavar='TOPIC',
          help="the node's offsets topic: when the bag recorded it, what the node published on it is "
               'shown first, and is all that is shown of a bag without event topics (default /evsync/offsets)')
    bagopts.add_stretch(a, whole='default 0')
    bagopts.add_selection(a, method_help='refined (default) or paper',
                          latency_help='known envelope latency of a camera')


def run(args: argparse.Namespace) -> int:
    src = Path(args.source)
    output_file(args.plot, option='--plot')
    if src.is_file() and src.suffix == '.json':
        return _from_json(args, src)
    with BagReader(src) as reader:
        made = reader.provenance
        recorded = any(c.topic == args.offsets_topic for c in reader.connections)
        events = any(is_event_type(c.msgtype) for c in reader.connections)
    if made is not None:
        print(f'{args.source} was restamped by evsync: {bagopts.made(made)}')
        print(tables.provenance_table(made) + '\n')
    if recorded:  # what evsync_node knew as the bag was recorded (its offsets topic recorded with the rig)
        _recorded(args, src, events=events)
        if not events:
            return Exit.DONE
    elif not events:
        raise EvsyncError(f'{src}: no event topic to estimate from, and no {args.offsets_topic} recorded to show')
    return _estimated(args)


def _from_json(args: argparse.Namespace, src: Path) -> int:
    if args.start is not None or args.duration is not None:
        raise EvsyncError(f'{src}: --start and --duration are for bags, not an estimate JSON')
    rig = load_rig(src)
    print(tables.offsets_table(rig))
    if args.plot:
        print(f'wrote {plots.plot(args.plot, rig, title=str(src))}')
    return status_of(rig, bag=str(src))  # as the estimate that wrote it: a camera not accepted is 1


def _recorded(args: argparse.Namespace, src: Path, *, events: bool) -> None:
    """The offsets the node published on its topic while the bag was recorded, and their plot."""
    tracks = restamp.load_offsets_stream(src, topic=args.offsets_topic)
    print(tables.recorded_offsets_table(tracks, topic=args.offsets_topic) + '\n')
    if args.plot:
        drawn = plots.plot_recorded(_recorded_plot(args.plot) if events else args.plot, tracks,
                                    title=f'{args.source}: {args.offsets_topic}')
        print(f'wrote {drawn}\n')


def _estimated(args: argparse.Namespace) -> int:
    """The bag's estimate: the offsets, each camera's windows, the plots."""
    est = bagopts.bag_estimate(args, args.source)
    params = refined.RefinedParams()
    print(f'{args.source}: method {args.method}{bagopts.stretch(args)}, {est.passes} pass(es) over the bag, '
          f'at most {est.peak_bin_bytes / 1e6:.1f} MB of binned counts held\n')
    print(tables.offsets_table(est.rig, events={t: r.events for t, r in est.reports.items()}))
    if est.windows:
        print()
        print(tables.history_table((est.timeline or est.rig).cameras, est.windows, binned=_binned(est)))
    if args.plot:
        if not est.windows and Method.of(args.method) is Method.PAPER:  # (refined, one camera: its offset alone)
            raise EvsyncError('plots are drawn from the refined method\'s windows; use --method refined')
        drawn = plots.plot(args.plot, est.timeline or est.rig, windows=est.windows, tau_ns=params.tau_ns,
                           title=str(args.source), binned=_binned(est))
        print(f'\nwrote {drawn}')
    return status_of(est.rig, bag=args.source)


def _binned(est: estimate.BagEstimate) -> Mapping[str, ClockCorrection]:
    """The correction each camera's kept windows were binned through (``BagEstimate.binned``: a
    de-skewed pass's windows are offsets on the de-skewed timeline)."""
    return est.binned


def _recorded_plot(plot: str) -> Path:
    """Where ``report --plot FILE.png`` draws a bag's recorded offsets when the estimate's figure takes
    FILE.png: FILE-offsets.png."""
    p = Path(plot)
    return p.with_name(f'{p.stem}-offsets{p.suffix or ".png"}')


COMMAND = Command(name='report', help='offsets table, offset history and plots from a rosbag2 or an estimate JSON',
                  declare=declare, run=run)
