"""evsync restamp BAG OUT: a copy of a bag with every event topic on the reference timeline; several
bags into --output-dir (or beside themselves with --suffix), each alone, as estimate does."""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from evsync_ros.bag import pipeline, restamp
from evsync_ros.bag.events import camera_topics
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.writer import COMPRESSION_FORMATS, COMPRESSION_MODES, Compression, Layout
from evsync_ros.cli import bagopts, batch, tables
from evsync_ros.cli.command import Arguments, Command, Exit, output_file
from evsync_ros.cli.progress import Progress
from evsync_ros.core.clock import ClockCorrection, CorrectionTrack
from evsync_ros.core.host import HOST
from evsync_ros.core.results import RigFit, load_rig
from evsync_ros.errors import EvsyncError

__all__ = ['COMMAND']

USAGE = ('evsync restamp [options] BAG OUT\n       evsync restamp [options] BAG [BAG ...] '
         '(--output-dir DIR | --suffix S) [--jobs N] [--json]')


def declare(a: Arguments) -> None:
    a.add('bag', nargs='+', metavar='BAG',
          help='BAG OUT: the input rosbag2 or ROS 1 .bag (only read) and the output bag directory (must not '
               'exist; a name ending in .bag: a ROS 1 bag). With --output-dir or --suffix: every path is an '
               'input, each restamped alone, then a summary (--jobs)')
    a.add('--output-dir', metavar='DIR',
          help='several bags: write each into DIR (created if missing) under its own name (with --suffix)')
    a.add('--json', action='store_true',
          help='with --output-dir or --suffix: print one JSON object, {"bags": [...]}, one entry per bag '
               '(instead of the tables)')
    a.add('--suffix', metavar='S',
          help="several bags: each output's name is its input's with S added (before .bag); beside its "
               'input unless --output-dir')
    a.add('--offsets', metavar='FILE.json|BAG',
          help='use the offsets of evsync estimate --json instead of estimating, or a bag\'s recorded '
               '/evsync/offsets (what evsync_node knew as it ran, drift included; the input itself when '
               'it was recorded with them)')
    a.add('--offsets-topic', default=restamp.OFFSETS_TOPIC, metavar='TOPIC',
          help='with --offsets BAG: the node\'s offsets topic (default /evsync/offsets)')
    a.add('--storage', choices=('sqlite3', 'mcap'),
          help='rosbag2 output storage (default: the input\'s; mcap for a ROS 1 input)')
    a.add('--record-time', choices=restamp.RECORD_TIME, default='auto',
          help='record timestamps of restamped topics: moved with header.stamp, kept, or auto (default: '
               'moved when the header is stamped with the recorder\'s clock)')
    a.add('--companion', action='append', metavar='TOPIC=EVENT_TOPIC',
          help="a topic on an event camera's clock (its IMU, frames, camera_info: any type beginning "
               "with a std_msgs/Header), restamped with that camera's correction, header.stamp only "
               '(repeatable)')
    a.add('--force', action='store_true', help='restamp even cameras whose estimate was not accepted')
    a.add('--compression-mode', choices=COMPRESSION_MODES, default='none',
          help="a rosbag2 output's compression, as ros2 bag record takes it: none (default), file (each storage "
               "file compressed whole) or message (each message's data)")
    a.add('--compression-format', choices=COMPRESSION_FORMATS, help='the compressor of --compression-mode')
    a.add('--max-bag-size', type=int, default=0, metavar='BYTES',
          help='split a rosbag2 output as ros2 bag record does: a new storage file once one holds BYTES of '
               'messages (default 0: not by size)')
    a.add('--max-bag-duration', type=float, default=0.0, metavar='S',
          help='split a rosbag2 output: a new storage file once the next message is S seconds of record time '
               'after the first of the current one (default 0: not by time); with --max-bag-size, whichever '
               'comes first')
    bagopts.add_jobs(a)
    bagopts.add_stretch(a, whole='the whole bag is restamped')
    bagopts.add_selection(a, method_help='refined (default) or paper',
                          latency_help='known envelope latency of a camera')


def least(argv: Sequence[str]) -> int | None:
    """The fewest positionals of a command line: BAG OUT, unless the outputs are named by --output-dir
    or --suffix (then one bag or more, as the parser says)."""
    named = any(a.split('=', 1)[0] in ('--output-dir', '--suffix') for a in argv)
    return None if named else 2


def run(args: argparse.Namespace) -> int:
    """``evsync restamp BAG OUT``, or several bags into ``--output-dir`` or beside themselves with
    ``--suffix`` (``batch.many``)."""
    if args.output_dir is None and args.suffix is None:
        if len(args.bag) != 2:
            raise EvsyncError(f'restamp takes BAG OUT, or several bags with --output-dir DIR or --suffix S '
                              f'(got {len(args.bag)} path(s): {" ".join(args.bag)})')
        if args.json:
            raise EvsyncError('restamp --json gives the summary of several bags: name their outputs with '
                              '--output-dir DIR or --suffix S (restamp BAG OUT prints its tables)')
        args.bag, args.out = args.bag
        return run_one(args).status
    plans = batch.outputs(args.bag, directory=args.output_dir, suffix=args.suffix or '')
    for plan in plans:  # before any bag is run
        layout(args).check(str(plan.output))
    if args.output_dir is not None:
        Path(args.output_dir).mkdir(parents=True, exist_ok=True)
    return batch.many(args, plans, restamp=True)


@dataclass
class _Source:
    """Where a restamp's corrections come from: an estimate of the bag, or offsets given."""

    reference: str
    corrections: dict[str, ClockCorrection]
    provenance: dict[str, Any]
    tracks: dict[str, CorrectionTrack] = field(default_factory=dict)
    rig: RigFit | None = None
    """The estimate made (None: offsets given)."""


def run_one(args: argparse.Namespace) -> batch.Ran:
    """``evsync restamp BAG OUT`` of one bag: the corrections, the copy, and what it did."""
    if Path(args.out).exists():
        raise EvsyncError(f'{args.out}: exists already; refusing to overwrite it')
    output_file(args.out, option='OUT')  # (the writer says so too, but only after the whole estimate)
    written = layout(args)
    written.check(args.out)  # before anything is estimated
    companions = _companions(args.companion)
    if not args.offsets and args.reference != HOST:
        _refuse_alone(args)
    source = _given(args) if args.offsets else _estimated(args)
    if args.offsets and source.reference != HOST:  # (offsets onto host time make one camera a rig)
        _refuse_uncorrected(args, source)
    bar = Progress(f'restamping into {Path(args.out).name}')
    t0 = time.perf_counter()
    try:
        rep = restamp.restamp_bag(args.bag, args.out, corrections=source.corrections, reference=source.reference,
                                  storage=args.storage, companions=companions, record_time=args.record_time,
                                  progress=bar, provenance=source.provenance, tracks=source.tracks,
                                  parallel=pipeline.available(jobs=getattr(args, 'jobs', 1)), layout=written)
    finally:
        bar.close()
    _say(args, rep, written, seconds=time.perf_counter() - t0, reference=source.reference)
    rig = source.rig
    forced = bool(source.provenance.get('forced'))  # a camera not accepted was applied: done, not all of it
    return batch.Ran(status=int(Exit.INCOMPLETE if rep.bad or forced else Exit.DONE), output=str(rep.output),
                     accepted=None if rig is None else sum(c.accepted for c in rig.cameras),
                     cameras=None if rig is None else len(rig.cameras), estimate=None if rig is None else rig.as_json())


def layout(args: argparse.Namespace) -> Layout:
    """The output's compression and splitting, as the options give them."""
    return Layout(compression=Compression(args.compression_mode), compression_format=args.compression_format or '',
                  max_bytes=args.max_bag_size, max_duration_ns=round(args.max_bag_duration * 1e9))


def _refuse_alone(args: argparse.Namespace) -> None:
    """A bag of one event camera: a copy would change nothing, an error before anything is read or written."""
    with BagReader(args.bag) as reader:
        events = [t for t in camera_topics(reader) if not args.topics or t in args.topics]
    if len(events) == 1:
        raise EvsyncError(f'{bagopts.alone(args.bag, events[0])}; nothing written')


def _refuse_uncorrected(args: argparse.Namespace, source: _Source) -> None:
    """Offsets given that correct no camera of the bag (of ``--topics``) but the reference: the copy would
    change nothing, as of a bag of one camera (another camera's offset onto a reference recorded
    elsewhere does change it)."""
    with BagReader(args.bag) as reader:
        events = [t for t in camera_topics(reader) if not args.topics or t in args.topics or t == source.reference]
    if any(t != source.reference and (t in source.corrections or t in source.tracks) for t in events):
        return
    if events == [source.reference]:
        raise EvsyncError(f'{bagopts.alone(args.bag, source.reference)}; nothing written')
    raise EvsyncError(f'{args.offsets}: corrects no camera of {args.bag} but the reference {source.reference}: nothing '
                      'to synchronise; nothing written')


def _given(args: argparse.Namespace) -> _Source:
    """--offsets: an estimate's JSON, or a bag's recorded offsets stream."""
    if args.start is not None or args.duration is not None:
        raise EvsyncError('--start and --duration choose the stretch to estimate from; with --offsets '
                          'nothing is estimated (the whole bag is restamped either way)')
    tracks: dict[str, CorrectionTrack] = {}
    if Path(args.offsets).suffix == '.json':
        rig = load_rig(args.offsets)
        reference, corrections = rig.reference, rig.corrections
        refused = _refused(args, rig, source=args.offsets)
        provenance: dict[str, Any] = {'offsets_file': str(Path(args.offsets).resolve()),
                                      'estimate': json.loads(Path(args.offsets).read_text()), 'forced': bool(refused)}
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
    return _Source(reference, corrections, provenance, tracks)  # (nothing estimated: no rig to report)


def _estimated(args: argparse.Namespace) -> _Source:
    """The bag's own estimate (its table printed), refused unless every camera is accepted or --force."""
    est = bagopts.bag_estimate(args, args.bag)
    print(tables.offsets_table(est.rig, events={t: r.events for t, r in est.reports.items()}))
    refused = _refused(args, est.rig, source=args.bag)
    provenance = {'method': args.method, 'estimate': est.rig.as_json(), 'forced': bool(refused)}
    if args.start is not None or args.duration is not None:
        provenance['estimated_from_s'] = {'start': args.start or 0.0, 'duration': args.duration}
    return _Source(est.rig.reference, est.rig.corrections, provenance, rig=est.rig)


def _refused(args: argparse.Namespace, rig: RigFit, *, source: str) -> list[str]:
    """The cameras of ``rig`` to be restamped whose estimate was not accepted: EvsyncError naming
    ``source`` (nothing written), or with --force a warning, and they are applied."""
    refused = [c.topic for c in rig.cameras if not c.accepted and (not args.topics or c.topic in args.topics)]
    if refused and not args.force:
        raise EvsyncError(f'{source}: no accepted estimate for {", ".join(refused)}; nothing written '
                          '(--force restamps with the best rejected estimate)')
    if refused:
        print(f'evsync: warning: --force: {", ".join(refused)} restamped with an estimate not accepted',
              file=sys.stderr)
    return refused


def _stream_reference(args: argparse.Namespace, tracked: list[str]) -> str:
    """The reference of a recorded offsets stream: --reference, else the one event topic of the input
    with no recorded correction (the node publishes none for its reference), else host when every
    camera has them."""
    if args.reference:
        return str(args.reference)
    with BagReader(args.bag) as reader:
        events = camera_topics(reader)
    untracked = [t for t in events if t not in tracked]
    if len(untracked) == 1:
        return untracked[0]
    if not untracked:
        return HOST
    raise EvsyncError(f'{args.offsets}: the offsets name {", ".join(tracked) or "no camera"}; the event topics '
                      f'{", ".join(untracked)} have none, so which is the reference? Give --reference')


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


_RECORD = {None: 'as recorded', True: 'moved with header.stamp', False: 'kept (a header not on the recorder\'s clock)'}
"""What became of a topic's record timestamps, by ``TopicCopy.record_shifted``."""


def _say(args: argparse.Namespace, rep: restamp.RestampReport, written: Layout, *, seconds: float,
         reference: str) -> None:
    """What was written: the output, each topic's messages, and on standard error what was not restamped."""
    if rep.previous is not None:
        print(f'evsync: warning: {args.bag} was restamped by evsync already ({bagopts.made(rep.previous)}): these '
              'corrections were applied on top of those', file=sys.stderr)
    for stale in rep.stale_removed:
        print(f'evsync: removed {stale}, the partial output of a run that was killed', file=sys.stderr)
    print(f'\nwrote {rep.output} ({rep.storage}{_laid_out(rep, written)}) in {seconds:.1f} s; '
          + ('what was applied is in its metadata (evsync report shows it)' if rep.provenance is not None else
             'a ROS 1 bag has no metadata to record what was applied in'))
    head = f'{"topic":<28} {"type":<36} {"messages":>9} {"restamped":>9}  record timestamps'
    print(head)
    print('-' * len(head))
    for topic, t in rep.topics.items():
        record = 'as recorded (the reference: moved by 0)' if topic == reference else _RECORD[t.record_shifted]
        print(f'{topic:<28} {t.msgtype:<36} {t.messages_out:>9,} {t.restamped:>9,}  {record}')
    _warn_unwritten(rep.topics)


def _laid_out(rep: restamp.RestampReport, written: Layout) -> str:
    """', 3 files, zstd per message' of a split or compressed output ('' of one plain file)."""
    if written.plain:
        return ''
    files = f', {len(rep.files)} file{"s" if len(rep.files) != 1 else ""}' if written.splits else ''
    how = {Compression.FILE: 'per file', Compression.MESSAGE: 'per message'}.get(written.compression)
    return files + (f', {written.compression_format} {how}' if how else '')


def _warn_unwritten(topics: Mapping[str, restamp.TopicCopy]) -> None:
    for topic, t in topics.items():
        if t.unconvertible:
            print(f'evsync: {topic}: {t.unconvertible} ROS 1 messages do not match their definition and have no '
                  f'ROS 2 form: not written (first: {t.first_error}); write a .bag output to keep them',
                  file=sys.stderr)
        if t.unchanged_bad:
            print(f'evsync: {topic}: {t.unchanged_bad} messages could not be restamped and were written unchanged '
                  f'(first: {t.first_error})', file=sys.stderr)
        if t.stamps is not None and t.stamps.disagreeing:
            print(f'evsync: warning: {t.stamps.says()}', file=sys.stderr)


COMMAND = Command(name='restamp', help='write a copy of a rosbag2 with every event topic on the reference timeline',
                  usage=USAGE, declare=declare, run=run, least=least, defaults={'one': run_one})
