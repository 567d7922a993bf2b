"""``evsync play``: the command line of ``ros.play`` (rclpy is loaded only for it)."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from collections.abc import Sequence

import rclpy
import rclpy.utilities
from rclpy.executors import ExternalShutdownException
from rclpy.signals import SignalHandlerOptions

from evsync_ros.cli.argv import positionals_last
from evsync_ros.errors import EXPECTED_ERRORS
from evsync_ros.ros.play import CLOCK_HZ, play


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog='evsync play', description='publish a rosbag2 over ROS at its recorded pace, '
                                 'as ros2 bag play does',
                                 epilog='ROS arguments go after --ros-args (evsync play BAG --ros-args -r '
                                        '__ns:=/rig); any other option is refused.')
    ap.add_argument('bag')
    ap.add_argument('--topics', nargs='+', help='only these topics')
    ap.add_argument('--rate', type=float, default=1.0, help='speed factor (2: twice as fast)')
    ap.add_argument('--remap', nargs='+', default=[], metavar='FROM:=TO', help='publish topic FROM on TO')
    force = ap.add_mutually_exclusive_group()
    force.add_argument('--best-effort', action='store_true',
                       help='best-effort QoS for every topic (default: each topic\'s recorded QoS, else reliable)')
    force.add_argument('--reliable', action='store_true', help='reliable QoS for every topic')
    ap.add_argument('--wait-subscribers', type=int, default=0, metavar='N',
                    help='start once each topic played that someone subscribes to has N subscribers '
                         '(topics nobody subscribes to are not waited for)')
    ap.add_argument('--start-paused', action='store_true',
                    help='send nothing until the service /evsync_player/resume (std_srvs/srv/Trigger; under '
                         'the namespace given) is called, as ros2 bag play --start-paused')
    ap.add_argument('--clock', type=float, nargs='?', const=CLOCK_HZ, default=0.0, metavar='HZ',
                    help=f'publish /clock (rosgraph_msgs/Clock) at the bag\'s time, HZ times a second (default '
                         f'{CLOCK_HZ:g}), for nodes with use_sim_time')
    ap.add_argument('--start-offset', type=float, default=0.0, metavar='S',
                    help="start S seconds after the bag's first message")
    ap.add_argument('--playback-duration', type=float, metavar='S', help='play S seconds of the bag (default: to '
                                                                         'its end)')
    ap.add_argument('--loop', action='store_true', help='play again from the start when done, until Ctrl-C')
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """``evsync play BAG [options] [--ros-args ...]``: only what follows ``--ros-args`` goes to rclpy;
    an option not known here is refused (exit 2). Exit status 0 done (a ``--loop`` ended by
    Ctrl-C or SIGTERM too), 1 a clear error about the bag or a value, 2 an option not known or
    missing its value, 130 interrupted."""
    argv = list(sys.argv[1:] if argv is None else argv)
    cut = argv.index('--ros-args') if '--ros-args' in argv else len(argv)
    ap = build_parser()
    args = ap.parse_args(positionals_last(ap, _clock_flag(argv[:cut])))
    remap = {}
    for item in args.remap:
        src, sep, dst = item.partition(':=')
        if not sep or not src or not dst:
            print(f'evsync play: --remap wants FROM:=TO, got {item!r}', file=sys.stderr)
            return 2
        remap[src] = dst
    # Ctrl-C and SIGTERM stop the playing between messages (a --loop so ends normally), not rclpy's context
    rclpy.init(args=['evsync_play', *argv[cut:]], signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda signum, frame: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        reliable = True if args.reliable else False if args.best_effort else None
        sent = play(args.bag, topics=args.topics, rate=args.rate, remap=remap, reliable=reliable,
                    wait_subscribers=args.wait_subscribers, clock_hz=args.clock, start_offset_s=args.start_offset,
                    duration_s=args.playback_duration, loop=args.loop,
                    start_paused=args.start_paused, stop=stop)
    except EXPECTED_ERRORS as exc:
        print(f'evsync play: {exc}', file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        return 130
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        rclpy.utilities.try_shutdown()
    for topic, n in sent.items():
        print(f'{topic}: {n} messages')
    return 0


def _clock_flag(argv: list[str]) -> list[str]:
    """``--clock`` followed by something not a rate (the bag, say) as ``--clock`` alone: its rate is
    optional, and argparse would take the bag for it."""
    out = list(argv)
    for i, token in enumerate(out[:-1]):
        if token == '--clock':
            try:
                float(out[i + 1])
            except ValueError:
                out[i] = f'--clock={CLOCK_HZ:g}'
    return out

