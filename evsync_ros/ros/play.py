"""evsync play: publish a rosbag2's messages at their recorded pace (ros2 bag play is not on PyPI).

Messages are published raw (their CDR bytes as recorded), one publisher per topic with the bag's
message type, spaced by their record timestamps divided by ``rate``; each topic with the QoS it was
recorded with (as ``ros2 bag play`` does: a driver's best-effort events stay best effort, a latched
camera_info transient local), or reliable where the bag recorded none (``--reliable`` and
``--best-effort`` force one for all). With ``wait_subscribers``,
nothing is sent until every topic has that many subscribers, so a node started beside the player
misses nothing. rclpy front end over ``bag.reader``.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

import rclpy
import rclpy.utilities
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import Connection, QosDurability, QosHistory, QosReliability

from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.ros1 import Unconverted
from evsync_ros.errors import EXPECTED_ERRORS, BagError, ParameterError
from evsync_ros.ros.messages import message_class


def play(bag: str, *, topics: Sequence[str] | None = None, rate: float = 1.0, remap: dict[str, str] | None = None,
         reliable: bool | None = None, depth: int = 1000, wait_subscribers: int = 0, wait_timeout_s: float = 30.0,
         context: Context | None = None) -> dict[str, int]:
    """Publish the bag; returns messages sent per (output) topic. ``reliable`` None: each topic's
    recorded QoS (``recorded_qos``); True or False: reliable or best effort for all, ``depth`` deep."""
    if not rate > 0:
        raise ParameterError(f'rate must be positive, got {rate!r}')
    remap = dict(remap or {})
    node = rclpy.create_node('evsync_player', context=context)
    sent: dict[str, int] = {}
    try:
        forced = None if reliable is None else QoSProfile(
            depth=depth, reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT)
        with BagReader(bag) as reader:
            conns = [c for c in reader.connections if topics is None or c.topic in topics]
            missing = sorted(set(topics or ()) - {c.topic for c in conns})
            if missing:
                raise BagError(f'{bag}: no topic {", ".join(missing)}')
            pubs = {c.topic: node.create_publisher(message_class(c.msgtype), remap.get(c.topic, c.topic),
                                                   forced or recorded_qos(c, depth=depth))
                    for c in conns}
            sent = {remap.get(t, t): 0 for t in pubs}
            if wait_subscribers:
                deadline = time.monotonic() + wait_timeout_s
                while any(p.get_subscription_count() < wait_subscribers for p in pubs.values()):
                    if time.monotonic() > deadline:
                        short = [t for t, p in pubs.items() if p.get_subscription_count() < wait_subscribers]
                        raise BagError(f'{bag}: no {wait_subscribers} subscribers on {", ".join(short)} '
                                       f'after {wait_timeout_s:g} s')
                    time.sleep(0.05)
            first: int | None = None
            start = 0
            for conn, stamp, raw in reader.messages(list(pubs)):
                if first is None:
                    first, start = stamp, time.monotonic_ns()
                delay = (start + (stamp - first) / rate - time.monotonic_ns()) / 1e9
                if delay > 0:
                    time.sleep(delay)
                if isinstance(raw, Unconverted):  # a ROS 1 message with no ROS 2 form: said, not sent
                    node.get_logger().warning(f'{conn.topic}: message at {stamp} not played: {raw.error}')
                    continue
                pubs[conn.topic].publish(bytes(raw))
                sent[remap.get(conn.topic, conn.topic)] += 1
        time.sleep(0.5)  # let the last messages leave before the publishers go
    finally:
        node.destroy_node()
    return sent


def recorded_qos(conn: Connection, *, depth: int = 1000) -> QoSProfile:
    """The QoS a topic was recorded with: a rosbag2's first offered profile (reliability, durability,
    its depth when it kept the last N), a ROS 1 bag's latching as transient local; reliable,
    ``depth`` deep, where the bag says nothing."""
    profiles = getattr(conn.ext, 'offered_qos_profiles', None) or []
    qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
    if getattr(conn.ext, 'latching', 0):
        qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
    if profiles:
        p = profiles[0]
        if p.reliability == QosReliability.BEST_EFFORT:
            qos.reliability = ReliabilityPolicy.BEST_EFFORT
        if p.durability == QosDurability.TRANSIENT_LOCAL:
            qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
        if p.history == QosHistory.KEEP_LAST and p.depth > 0:
            qos.depth = p.depth
    return qos


def main(argv: Sequence[str] | None = None) -> int:
    """``evsync play BAG [--topics ...] [--rate R] [--remap FROM:=TO ...] [--best-effort]
    [--wait-subscribers N]``; ROS arguments after the options go to rclpy."""
    ap = argparse.ArgumentParser(prog='evsync play', description=__doc__.split('\n')[0])
    ap.add_argument('bag')
    ap.add_argument('--topics', nargs='+', help='only these topics')
    ap.add_argument('--rate', type=float, default=1.0, help='speed factor (2: twice as fast)')
    ap.add_argument('--remap', nargs='+', default=[], metavar='FROM:=TO', help='publish topic FROM on TO')
    force = ap.add_mutually_exclusive_group()
    force.add_argument('--best-effort', action='store_true',
                       help='best-effort QoS for every topic (default: each topic\'s recorded QoS, else reliable)')
    force.add_argument('--reliable', action='store_true', help='reliable QoS for every topic')
    ap.add_argument('--wait-subscribers', type=int, default=0, metavar='N',
                    help='start once every topic has N subscribers')
    args, ros_args = ap.parse_known_args(argv)
    remap = {}
    for item in args.remap:
        src, sep, dst = item.partition(':=')
        if not sep or not src or not dst:
            print(f'evsync play: --remap wants FROM:=TO, got {item!r}', file=sys.stderr)
            return 2
        remap[src] = dst
    rclpy.init(args=['evsync_play', *ros_args])
    try:
        reliable = True if args.reliable else False if args.best_effort else None
        sent = play(args.bag, topics=args.topics, rate=args.rate, remap=remap, reliable=reliable,
                    wait_subscribers=args.wait_subscribers)
    except EXPECTED_ERRORS as exc:
        print(f'evsync play: {exc}', file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        return 130
    finally:
        rclpy.utilities.try_shutdown()
    for topic, n in sent.items():
        print(f'{topic}: {n} messages')
    return 0
