"""evsync play: the command line of ros.play, which publishes a bag over ROS as ros2 bag play does
(rclpy is loaded only when it runs)."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from collections.abc import Sequence
from typing import Any

from evsync_ros.cli.command import Arguments, Command, Exit
from evsync_ros.errors import EXPECTED_ERRORS

__all__ = ['COMMAND']

ROS_ARGS = '--ros-args'


def declare(a: Arguments) -> None:
    """The options of ros2 bag play that apply here, with its short flags (-r, -l, -p, -d, -s, -m)."""
    from evsync_ros.ros.play import CLOCK_HZ

    a.add('bag')
    a.add('--topics', nargs='+', help='only these topics')
    a.add('-r', '--rate', type=float, default=1.0, help='speed factor (2: twice as fast)')
    a.add('-m', '--remap', nargs='+', default=[], metavar='FROM:=TO', help='publish topic FROM on TO')
    force = a.exclusive()
    a.add('--best-effort', action='store_true', group=force,
          help='best-effort QoS for every topic (default: each topic\'s recorded QoS, else reliable)')
    a.add('--reliable', action='store_true', group=force, help='reliable QoS for every topic')
    a.add('--qos-profile-overrides-path', metavar='FILE.yaml',
          help='the QoS of the topics it names (their names in the bag), over their recorded QoS and --reliable '
               'or --best-effort, in the YAML of ros2 bag play\'s option: /topic: {reliability: reliable, depth: '
               '10, ...}')
    a.add('--wait-subscribers', type=int, default=0, metavar='N',
          help='start once each topic played that someone subscribes to has N subscribers '
               '(topics nobody subscribes to are not waited for)')
    a.add('-p', '--start-paused', action='store_true',
          help='send nothing until the service /evsync_player/resume (std_srvs/srv/Trigger; under '
               'the namespace given) is called, as ros2 bag play --start-paused')
    a.add('--clock', type=float, nargs='?', const=CLOCK_HZ, default=0.0, metavar='HZ',
          help=f'publish /clock (rosgraph_msgs/Clock) at the bag\'s time, HZ times a second (default '
               f'{CLOCK_HZ:g}), for nodes with use_sim_time')
    a.add('--start-offset', type=float, default=0.0, metavar='S', help="start S seconds after the bag's first message")
    a.add('--playback-duration', type=float, metavar='S', help='play S seconds of the bag (default: to its end)')
    a.add('-d', '--delay', type=float, default=0.0, metavar='S',
          help='wait S seconds before playing, and before each pass of --loop (/clock held at the start)')
    a.add('-l', '--loop', action='store_true', help='play again from the start when done, until Ctrl-C')
    a.add('-s', '--storage', choices=('sqlite3', 'mcap'),
          help="the bag's storage, as ros2 bag play takes it; evsync play finds it by itself, and refuses a "
               'bag that is not in the storage named')


def split(argv: list[str]) -> tuple[list[str], dict[str, Any]]:
    """The words the parser takes (those before --ros-args, ``--clock`` followed by no rate as
    ``--clock`` alone: argparse would take the bag for its rate), and what follows --ros-args, for
    rclpy alone."""
    from evsync_ros.ros.play import CLOCK_HZ

    cut = argv.index(ROS_ARGS) if ROS_ARGS in argv else len(argv)
    words = list(argv[:cut])
    for i, token in enumerate(words[:-1]):
        if token == '--clock' and not _number(words[i + 1]):
            words[i] = f'--clock={CLOCK_HZ:g}'
    return words, {'ros_args': argv[cut:]}


def _number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def run(args: argparse.Namespace) -> int:
    """Play the bag: only what follows --ros-args goes to rclpy; Ctrl-C and SIGTERM stop the playing
    between messages, and end it with 130 whatever it was doing (waiting, paused, playing, looping)."""
    import rclpy
    import rclpy.utilities
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions

    from evsync_ros.ros.play import load_qos_overrides, play

    remap = _remaps(args.remap)
    if remap is None:
        return Exit.ERROR
    rclpy.init(args=['evsync_play', *args.ros_args], signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda signum, frame: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        overrides = load_qos_overrides(args.qos_profile_overrides_path) if args.qos_profile_overrides_path else {}
        reliable = True if args.reliable else False if args.best_effort else None
        sent = play(args.bag, topics=args.topics, rate=args.rate, remap=remap, reliable=reliable,
                    wait_subscribers=args.wait_subscribers, clock_hz=args.clock, start_offset_s=args.start_offset,
                    duration_s=args.playback_duration, loop=args.loop, start_paused=args.start_paused,
                    delay_s=args.delay, storage=args.storage, qos_overrides=overrides, stop=stop)
    except EXPECTED_ERRORS as exc:
        print(f'evsync play: {exc}', file=sys.stderr)
        return Exit.INCOMPLETE
    except (KeyboardInterrupt, ExternalShutdownException):
        return Exit.INTERRUPTED
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        rclpy.utilities.try_shutdown()
    for topic, n in sent.items():
        print(f'{topic}: {n} messages')
    return Exit.INTERRUPTED if stop.is_set() else Exit.DONE


def _remaps(items: Sequence[str]) -> dict[str, str] | None:
    """--remap FROM:=TO ... as {from: to} (None, said, when one is not of that form)."""
    remap = {}
    for item in items:
        src, sep, dst = item.partition(':=')
        if not sep or not src or not dst:
            print(f'evsync play: --remap wants FROM:=TO, got {item!r}', file=sys.stderr)
            return None
        remap[src] = dst
    return remap


COMMAND = Command(name='play', help='publish a rosbag2 over ROS at its recorded pace (needs rclpy; evsync play --help)',
                  description='publish a rosbag2 over ROS at its recorded pace, as ros2 bag play does',
                  epilog='ROS arguments go after --ros-args (evsync play BAG --ros-args -r __ns:=/rig); any other '
                         'option is refused.',
                  declare=declare, run=run, split=split, interrupted='')
