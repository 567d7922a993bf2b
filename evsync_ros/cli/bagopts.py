"""What ``evsync estimate``, ``restamp`` and ``report`` share: the options that choose what is estimated
from a bag, the estimate they run with them, and what they say of it."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from evsync_ros.bag import pipeline
from evsync_ros.bag.edges import channels_given, read_edges
from evsync_ros.bag.reader import BagReader
from evsync_ros.cli.command import Arguments
from evsync_ros.cli.progress import Progress
from evsync_ros.core import lazy
from evsync_ros.core.host import HOST
from evsync_ros.core.latencies import Latencies, combined
from evsync_ros.core.results import METHODS, PriorChoice, RigFit
from evsync_ros.core.triggers import edge_anchor, tie
from evsync_ros.errors import EvsyncError, StreamError

if TYPE_CHECKING:
    from evsync_ros.bag import estimate
else:  # what only an estimate runs, loaded when one does (restamp --offsets runs none of it)
    estimate = lazy.module('evsync_ros.bag.estimate')

__all__ = ['add_jobs', 'add_selection', 'add_stretch', 'alone', 'bag_estimate', 'made', 'ms', 'stretch']


def add_selection(a: Arguments, *, method_help: str, latency_help: str, host: bool = True) -> None:
    """--topics, --reference, --method, --latency-us: what is estimated against what (``host``: the
    command takes --reference host)."""
    a.add('--topics', nargs='+', help='event topics to use (default: every event topic)')
    a.add('--reference', help='reference topic (default: the first of --topics, else the first by name)'
                              + (", or 'host': every camera onto host (ROS) time" if host else ''))
    a.add('--method', choices=METHODS, default='refined', help=method_help)
    a.add('--latency-us', nargs='+', metavar='TOPIC=US', help=latency_help)
    a.add('--trigger-channel', nargs='+', metavar='TOPIC=ID',
          help="the trigger input a camera's shared pulse comes in on (verify: default, the one channel it has "
               'edges on); estimate, restamp, report: each camera named takes its line from its edges and the '
               "reference's (without the reference: another named camera's) once its density estimate picks the "
               'pulse (docs/triggers.md)')
    a.add('--latencies', metavar='FILE', help='known envelope latencies from a file evsync verify --save-latencies '
          'wrote (docs/triggers.md); a camera in it may not be given --latency-us too')


def add_stretch(a: Arguments, *, whole: str, host: bool = True) -> None:
    """--start, --duration, --host-latency-us: the stretch of the bag estimated from (``whole``: what
    is done when no --start is given; ``host``: the command takes --reference host)."""
    a.add('--start', type=float, metavar='S',
          help=f"estimate from the messages recorded from S seconds after the bag's first ({whole})")
    a.add('--duration', type=float, metavar='S',
          help='estimate from S seconds of the bag from --start on (default: to its end)')
    if host:
        a.add('--host-latency-us', type=float, metavar='US',
              help='with --reference host: the least latency from an event to the host, if known '
                   '(taken out; else host times are late by it)')
    a.add('--prior', choices=[c.value for c in PriorChoice], default=PriorChoice.AUTO.value,
          help="what places each camera's windows: auto (default: its record times where they behave as one "
               "clock's arrivals, else its events alone), arrival, or events")


def add_jobs(a: Arguments) -> None:
    a.add('-j', '--jobs', type=_jobs, default=1, metavar='N',
          help='several bags: how many at once, each in a process of its own (default 1)')


def _jobs(text: str) -> int:
    """--jobs N: a whole number, 1 or more."""
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f'wants a whole number of processes, 1 or more, got {text!r}')
    return n


def latencies(pairs: Sequence[str] | None) -> dict[str, int]:
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


def bag_estimate(args: argparse.Namespace, bag: str, label: str = 'estimating', *,
                 consistency: bool = False, edges: bool = True) -> estimate.BagEstimate:
    """The estimate the options ask for, of ``bag``, with a progress bar; what reading met said."""
    # a stretch's messages are only guessed from its share of the bag's span: a spinner for it
    bar = Progress(f'{label} {Path(bag).name}', exact=args.start is None and args.duration is None)
    try:
        host_latency_us = getattr(args, 'host_latency_us', None)  # (verify has none)
        if host_latency_us is not None and args.reference != HOST:
            raise EvsyncError('--host-latency-us is for --reference host')
        floor = round((host_latency_us or 0.0) * 1000)
        known = known_latencies(args, bag)
        est = estimate.estimate_bag(bag, topics=args.topics, reference=args.reference, method=args.method,
                                    latencies_ns=known, host_floor_ns=floor, progress=bar,
                                    start_s=args.start, duration_s=args.duration, consistency=consistency,
                                    parallel=pipeline.available(jobs=getattr(args, 'jobs', 1)), prior=args.prior)
    except StreamError as exc:  # what the estimate met: said of the bag (a session reads several)
        if str(exc).startswith(f'{bag}:'):
            raise
        raise StreamError(f'{bag}: {exc}') from exc
    finally:
        bar.close()
    if known:  # what was taken out, in the result (and so in a restamped bag's provenance)
        source = {'latencies_file': str(Path(args.latencies).resolve())} if args.latencies else {}
        est.rig = replace(est.rig, latencies={'latencies_ns': known, **source})
    if edges and args.trigger_channel:
        est.rig = on_edges(est.rig, bag, channels_given(args.trigger_channel))
    _warn_reading(est.reports, est.late_events, est.far_events)
    return est


def on_edges(rig: RigFit, bag: str, channels: Mapping[str, int]) -> RigFit:
    """``rig`` with each camera of ``channels`` tied edge to edge to the reference's edges, or where the
    reference has none given, to the edges of the camera known best (``triggers.tie``, the rule the
    node's engine decides by)."""
    if rig.reference not in channels and len(channels) < 2:
        raise EvsyncError(f'--trigger-channel: give the reference\'s channel ({rig.reference}=ID) or two cameras\' '
                          'channels: a camera\'s edges are tied to the reference\'s, or to another camera\'s')
    unknown = sorted(set(channels) - {c.topic for c in rig.cameras})
    if unknown:
        raise EvsyncError(f'--trigger-channel names {", ".join(unknown)}, which is not a camera of the estimate')
    read = read_edges(bag, list(channels), channels=channels)
    edges = {t: r.edges for t, r in read.items()}
    fits = {c.topic: c for c in rig.cameras if c.topic != rig.reference}
    anchor = edge_anchor(fits, edges, reference=rig.reference)
    return replace(rig, cameras=tuple(tie(c, fits, edges, reference=rig.reference, anchor=anchor)
                                      if c.topic in fits else c for c in rig.cameras))


def known_latencies(args: argparse.Namespace, bag: str) -> dict[str, int]:
    """--latencies FILE (its cameras that are event topics of ``bag``) and --latency-us together; an
    error for a camera given by both."""
    given = latencies(args.latency_us)
    if not args.latencies:
        return given
    file = Latencies.load(args.latencies)
    with BagReader(bag) as reader:
        topics = {c.topic for c in reader.connections}
    file = replace(file, latencies_ns={t: ns for t, ns in file.latencies_ns.items() if t in topics})
    return combined(file, given, source=args.latencies)


DECODED_NOTES = {'event outside the sensor geometry': ' (not used by the estimate; a restamp keeps them)'}
"""What becomes of what a decoder counted, where a user would ask (``_warn_reading``)."""


def _warn_reading(reports: Mapping[str, estimate.TopicReport], late: Mapping[str, int] | None = None,
                  far: Mapping[str, int] | None = None) -> None:
    for topic, rep in reports.items():
        if rep.undecodable:
            print(f'evsync: {topic}: {rep.undecodable} of {rep.messages} messages could not be decoded '
                  f'(first: {rep.first_error})', file=sys.stderr)
        if rep.anomalies:
            print(f'evsync: {topic}: counted while decoding: '
                  + ', '.join(f'{k} x{v}{DECODED_NOTES.get(k, "")}' for k, v in sorted(rep.anomalies.items())),
                  file=sys.stderr)
    for topic, n in (late or {}).items():
        print(f'evsync: {topic}: {n} events came too far out of order for their window and were not used',
              file=sys.stderr)
    for topic, n in (far or {}).items():
        print(f'evsync: {topic}: {n} events lie over a minute from the rest of their message (corrupt times) '
              'and were not used', file=sys.stderr)


def alone(bag: str, topic: str) -> str:
    """What is said of a bag with one event camera (and a camera, not the host, for reference)."""
    return (f'{bag}: one event topic, {topic}: nothing to synchronise it with (a bag of two cameras or more '
            'is; --reference host puts one camera on the host\'s clock)')


def stretch(args: argparse.Namespace) -> str:
    """', from 5 s for 10 s' of --start and --duration ('' for the whole bag)."""
    if args.start is None and args.duration is None:
        return ''
    return f', from {args.start or 0:g} s' + (f' for {args.duration:g} s' if args.duration is not None else ' on')


def made(record: Mapping[str, Any]) -> str:
    """How a restamped bag was made, in a line (its provenance)."""
    how = f"--offsets {record['offsets_file']}" if 'offsets_file' in record else f"method {record.get('method', '?')}"
    forced = ', with --force (a camera\'s estimate not accepted)' if record.get('forced') else ''
    return (f"evsync {record.get('evsync_version', '?')} at {record.get('written_utc', '?')}, from "
            f"{record.get('input', '?')}, {how}{forced}, reference {record.get('reference', '?')}")


def ms(ns: float) -> str:
    return f'{ns / 1e6:+.3f}'
