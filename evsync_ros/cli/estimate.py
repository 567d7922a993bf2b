"""evsync estimate BAG: every event topic's offset (and skew) against a reference, from a bag; several
bags each alone in a process of its own (--jobs), then a summary (cli.batch)."""

from __future__ import annotations

import argparse
import json
import sys
import time

from evsync_ros.cli import bagopts, batch, tables
from evsync_ros.cli.command import Arguments, Command, Exit
from evsync_ros.core.host import HOST
from evsync_ros.core.results import Method, RigFit

__all__ = ['COMMAND']


def declare(a: Arguments) -> None:
    a.add('bag', nargs='+', metavar='BAG',
          help='rosbag2 directory (sqlite3 or mcap), a single .db3/.mcap file, or a ROS 1 .bag; several: '
               'each estimated alone, then a summary (--jobs)')
    bagopts.add_selection(a, method_help='refined (default) or paper (the paper, faithfully)',
                          latency_help='known envelope latency of a camera in microseconds (taken out of its '
                                       'offset; see README)')
    a.add('--json', action='store_true',
          help='print exactly one JSON object (the estimate contract; several bags: {"bags": [...]}, '
               'one entry per bag)')
    a.add('--consistency', action='store_true',
          help='also estimate every camera pair and print the largest disagreement (holds all events in memory)')
    bagopts.add_jobs(a)
    bagopts.add_stretch(a, whole='default 0')


def run(args: argparse.Namespace) -> int:
    """One bag, or several (``batch.many``)."""
    if len(args.bag) > 1:
        return batch.many(args, [batch.Plan(bag) for bag in args.bag])
    args.bag = args.bag[0]
    return run_one(args).status


def run_one(args: argparse.Namespace) -> batch.Ran:
    """``evsync estimate BAG`` on one bag: the table (or the JSON) and what the exit status says."""
    t0 = time.perf_counter()
    est = bagopts.bag_estimate(args, args.bag, consistency=args.consistency)
    rig, reports = est.rig, est.reports
    elapsed = time.perf_counter() - t0
    status = status_of(rig, bag=args.bag)
    ran = batch.Ran(status=status, accepted=sum(c.accepted for c in rig.cameras), cameras=len(rig.cameras),
                    estimate=rig.as_json())
    if args.json:
        json.dump(rig.as_json(), sys.stdout)
        sys.stdout.write('\n')
        return ran
    print(f'{args.bag}: method {args.method}{bagopts.stretch(args)}, estimated in {elapsed:.2f} s\n')
    print(tables.offsets_table(rig, events={t: r.events for t, r in reports.items()}))
    if rig.pair_residual_ns:
        worst = max(rig.pair_residual_ns.items(), key=lambda kv: abs(kv[1]))
        print(f'\nconsistency over {len(rig.pair_residual_ns)} camera pairs: largest disagreement '
              f'{bagopts.ms(worst[1])} ms ({worst[0][0]} vs {worst[0][1]})')
    elif args.consistency and Method.of(args.method) is Method.REFINED:
        first = (est.timeline or rig).reference  # with reference host: the cameras were on this one's timeline
        others = sum(c.accepted for c in rig.cameras if c.topic != first)
        print(f'\nconsistency: no camera pair to check ({others} accepted camera(s) besides the reference; a pair '
              f'needs two, and its own estimate accepted)')
    elif args.consistency:
        print('\nconsistency: the pairs are checked with the refined method only')
    return ran


def status_of(rig: RigFit, *, bag: str) -> int:
    """An estimate's exit status: done when every camera is accepted; a bag of one camera (and a
    camera for reference) has nothing to synchronise, which is said on standard error."""
    alone = len(rig.cameras) == 1 and rig.reference != HOST
    if alone:  # the estimate (the reference alone) is printed as asked; the exit status says it did nothing
        print(f'evsync: {bagopts.alone(bag, rig.reference)}', file=sys.stderr)
    return int(Exit.DONE if all(c.accepted for c in rig.cameras) and not alone else Exit.INCOMPLETE)


COMMAND = Command(name='estimate', help='estimate every event topic\'s offset and skew in a rosbag2', declare=declare,
                  run=run, defaults={'one': run_one})
