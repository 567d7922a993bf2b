"""evsync plotjuggler: a PlotJuggler layout of the node's numeric status topics."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from evsync_ros.cli.command import Arguments, Command, Exit, output_file
from evsync_ros.core import lazy
from evsync_ros.errors import EvsyncError

if TYPE_CHECKING:
    from evsync_ros.ros import parameters as config
    from evsync_ros.ros import status
else:  # loaded when a layout is written
    config = lazy.module('evsync_ros.ros.parameters')
    status = lazy.module('evsync_ros.ros.status')

__all__ = ['COMMAND']


def declare(a: Arguments) -> None:
    a.add('--params-file', help="the node's parameter YAML: its topics and status_topic (default: the "
                                'shipped config/evsync.yaml)')
    a.add('--topics', nargs='+', help="event topics (instead of the parameter file's)")
    a.add('--status-topic', help="the node's status_topic (instead of the parameter file's)")
    a.add('-o', '--output', metavar='FILE.xml', help='layout to write (must not exist; default: standard '
                                                     'output); open it with plotjuggler --layout FILE.xml')


def run(args: argparse.Namespace) -> int:
    output_file(args.output, option='-o')
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
        return Exit.DONE
    try:
        with open(args.output, 'x', encoding='utf-8') as f:
            f.write(text)
    except FileExistsError as exc:
        raise EvsyncError(f'{args.output} exists; the layout is not written over it') from exc
    print(f'wrote {args.output}: {len(topics)} cameras under {status_topic}', file=sys.stderr)
    return Exit.DONE


COMMAND = Command(name='plotjuggler', help="write a PlotJuggler layout of evsync_node's numeric status topics "
                                           '(offset, its standard error, skew, state per camera)',
                  declare=declare, run=run)
