"""evsync play: publish a rosbag2's messages at their recorded pace, as ``ros2 bag play`` does (it is
not on PyPI).

Messages are published raw (their CDR bytes as recorded), one publisher per topic with the bag's
message type, spaced by their record timestamps divided by ``rate``; each topic with the QoS it was
recorded with (as ``ros2 bag play`` does: a driver's best-effort events stay best effort, a latched
camera_info transient local), or reliable where the bag recorded none (``--reliable`` and
``--best-effort`` force one for all). ``clock_hz``: rosgraph_msgs/Clock on /clock at the bag's time
(what the played messages were recorded at), for nodes with ``use_sim_time``. With
``wait_subscribers``, nothing is sent until the topics being played that someone subscribes to have
that many subscribers each. That is the player's view: a subscriber's side of the match can come
later, and what is sent before it is lost to that subscriber; with ``start_paused`` nothing is sent
until the ``resume`` service (std_srvs/Trigger, as ``ros2 bag play --start-paused`` waits for its
own) is called, once the subscribers say they have the player's topics. ``qos_overrides`` (from a
file of ``ros2 bag play --qos-profile-overrides-path``'s format, ``load_qos_overrides``) give the
topics they name their QoS, over the recorded and the forced one. rclpy front end over
``bag.reader``.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping, Sequence
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import rclpy
import rclpy.utilities
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, ShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    InvalidQoSProfileException,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rosbags.interfaces import Connection, QosDurability, QosHistory, QosReliability
from rosgraph_msgs.msg import Clock
from ruamel.yaml import YAML
from ruamel.yaml.error import YAMLError
from std_srvs.srv import Trigger

from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.ros1 import Unconverted
from evsync_ros.bag.storage import input_storage
from evsync_ros.errors import BagError, ParameterError
from evsync_ros.ros.messages import message_class

CLOCK_HZ = 40.0
"""``--clock`` without a rate: as ``ros2 bag play``."""
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST)
"""/clock as ``ros2 bag play`` offers it (rclcpp's ClockQoS), what rclpy's time source takes."""
SETTLE_S = 0.5
"""``wait_subscribers``: how long the subscribed topics must stay as they are before playing starts
(a node's subscriptions are discovered one by one)."""
LINGER_S = 0.5
"""After the last message, before the publishers go: time for it to leave."""


class Pace:
    """Bag time against this host's monotonic clock: the bag's time ``bag_ns`` when ``begin`` was
    called, then ``rate`` bag seconds per second (held at ``bag_ns`` before); /clock published at
    ``clock_hz`` (0: none) whenever the player waits."""

    def __init__(self, bag_ns: int, *, rate: float, clock: Publisher | None, clock_hz: float,
                 stop: threading.Event) -> None:
        self.rate = rate
        self.stop = stop
        self.clock = clock
        self.period_ns = round(1e9 / clock_hz) if clock is not None and clock_hz > 0 else 0
        self.bag_ns = bag_ns
        self.wall_ns: int | None = None
        self.next_tick = time.monotonic_ns()

    def begin(self, bag_ns: int) -> None:
        self.bag_ns, self.wall_ns = bag_ns, time.monotonic_ns()
        self.next_tick = self.wall_ns
        self.tick()

    def now(self) -> int:
        """The bag's time now."""
        if self.wall_ns is None:
            return self.bag_ns
        return self.bag_ns + round((time.monotonic_ns() - self.wall_ns) * self.rate)

    def tick(self) -> None:
        """/clock, when its period is due (one message: a late tick is not made up)."""
        if self.clock is None or not self.period_ns:
            return
        now = time.monotonic_ns()
        if now >= self.next_tick:
            self.clock.publish(_clock_msg(self.now()))
            self.next_tick = max(self.next_tick + self.period_ns, now)

    def hold(self, seconds: float, *, at_ns: int) -> bool:
        """Wait ``seconds`` with the bag's time held at ``at_ns`` (/clock published meanwhile: the
        delay before each pass, ``ros2 bag play --delay``); False when ``stop`` was set first."""
        self.bag_ns, self.wall_ns = at_ns, None
        end = time.monotonic_ns() + round(seconds * 1e9)
        while not self.stop.is_set():
            self.tick()
            now = time.monotonic_ns()
            if now >= end:
                return True
            wake = min(end, self.next_tick) if self.period_ns else end
            self.stop.wait(max(0, wake - now) / 1e9)
        return False

    def wait_until(self, bag_ns: int) -> bool:
        """Sleep until the bag's time reaches ``bag_ns``, publishing /clock meanwhile; False when
        ``stop`` was set first."""
        if self.wall_ns is None:
            self.begin(self.bag_ns)
        assert self.wall_ns is not None
        due = self.wall_ns + round((bag_ns - self.bag_ns) / self.rate)
        while not self.stop.is_set():
            self.tick()
            now = time.monotonic_ns()
            if now >= due:
                return True
            wake = min(due, self.next_tick) if self.period_ns else due
            self.stop.wait(max(0, wake - now) / 1e9)
        return False


def _clock_msg(ns: int) -> Clock:
    msg = Clock()
    msg.clock.sec, msg.clock.nanosec = divmod(ns, 1_000_000_000)
    return msg


def play(bag: str, *, topics: Sequence[str] | None = None, rate: float = 1.0, remap: dict[str, str] | None = None,
         reliable: bool | None = None, depth: int = 1000, wait_subscribers: int = 0, wait_timeout_s: float = 30.0,
         clock_hz: float = 0.0, start_offset_s: float = 0.0, duration_s: float | None = None, loop: bool = False,
         start_paused: bool = False, delay_s: float = 0.0, storage: str | None = None,
         qos_overrides: Mapping[str, QoSProfile] | None = None, stop: threading.Event | None = None,
         context: Context | None = None) -> dict[str, int]:
    """Publish the bag; returns messages sent per (output) topic. ``reliable`` None: each topic's
    recorded QoS (``recorded_qos``); True or False: reliable or best effort for all, ``depth`` deep;
    ``qos_overrides``: the QoS of each topic they name (the bag's name), over both. ``clock_hz``:
    /clock at the bag's time (0: none). ``start_offset_s``, ``duration_s``: play the stretch from
    that many seconds after the bag's first message, for that long (None: to its end). ``loop``:
    play it again and again, until ``stop`` is set. ``delay_s``: wait that long before each pass,
    /clock held at its start. ``start_paused``: nothing is sent before the player's ``~/resume``
    service is called (after ``wait_subscribers``, if any), /clock held at the start meanwhile.
    ``storage``: the storage the bag must be in ('sqlite3', 'mcap'; None: whichever it is).
    ``stop`` set (Ctrl-C) while playing: the playing stops there and what was sent is returned (the
    caller tells by ``stop``); set while waiting: KeyboardInterrupt."""
    _check_values(rate=rate, clock_hz=clock_hz, start_offset_s=start_offset_s, duration_s=duration_s,
                  delay_s=delay_s)
    check_storage(bag, storage)
    remap = dict(remap or {})
    node = rclpy.create_node('evsync_player', context=context)
    sent: dict[str, int] = {}
    try:
        with BagReader(bag) as reader:
            pubs = _publishers(node, bag, reader.connections, topics=topics, remap=remap, reliable=reliable,
                               depth=depth, overrides=qos_overrides or {})
            sent = {remap.get(t, t): 0 for t in pubs}
            window = reader.window_ns(start_offset_s, duration_s) if start_offset_s or duration_s else None
            begin = window[0] if window is not None else reader.start_ns
            stop = stop or threading.Event()
            pace = Pace(begin, rate=rate, clock_hz=clock_hz, stop=stop,
                        clock=node.create_publisher(Clock, '/clock', CLOCK_QOS) if clock_hz else None)
            if wait_subscribers:
                _wait_subscribers(bag, pubs, wait_subscribers, timeout_s=wait_timeout_s, pace=pace)
            with ExitStack() as serving:
                if start_paused:
                    _wait_resumed(serving.enter_context(_ResumeService(node)), pace)
                while not stop.is_set():
                    if delay_s and not pace.hold(delay_s, at_ns=begin):
                        break
                    pace.begin(begin)
                    _one_pass(node, reader, pubs, pace, sent=sent, remap=remap, window=window, rate=rate)
                    if not loop:
                        break
                pace.wait_until(pace.now() + round(LINGER_S * 1e9 * rate))  # the last messages leave, /clock runs on
    finally:
        node.destroy_node()
    return sent


def _check_values(*, rate: float, clock_hz: float, start_offset_s: float, duration_s: float | None,
                  delay_s: float) -> None:
    if not rate > 0:
        raise ParameterError(f'rate must be positive, got {rate!r}')
    if clock_hz < 0:
        raise ParameterError(f'--clock wants a rate in Hz > 0, got {clock_hz:g}')
    if start_offset_s < 0 or (duration_s is not None and not duration_s > 0):
        raise ParameterError(f'--start-offset must be >= 0 and --playback-duration > 0 seconds, got '
                             f'{start_offset_s:g} and {duration_s}')
    if not delay_s >= 0:
        raise ParameterError(f'--delay must be >= 0 seconds, got {delay_s!r}')


def check_storage(bag: str, storage: str | None) -> None:
    """ParameterError naming the bag when ``storage`` is given and the bag is not in it (``ros2 bag play
    -s``: its storage plugin; evsync reads a bag in whichever storage its files are, so ``-s`` can only
    name that one)."""
    if storage is None:
        return
    found = input_storage(bag)
    if found != storage:
        raise ParameterError(f'{bag}: its storage is {found}, not {storage} (-s/--storage names the storage of '
                             'the bag, which evsync play finds by itself; leave it out)')


def _one_pass(node: Node, reader: BagReader, pubs: dict[str, Publisher], pace: Pace, *, sent: dict[str, int],
              remap: Mapping[str, str], window: tuple[int, int] | None, rate: float) -> None:
    """The bag (its ``window``) once, paced; what the readers passed over, after a whole pass, is said
    (the BagError raised once the last messages have left), not lost unseen."""
    read = dict.fromkeys(pubs, 0)
    for conn, stamp, raw in reader.messages(list(pubs), window=window):
        if not pace.wait_until(stamp):
            return
        read[conn.topic] += 1
        if isinstance(raw, Unconverted):  # a ROS 1 message with no ROS 2 form: said, not sent
            node.get_logger().warning(f'{conn.topic}: message at {stamp} not played: {raw.error}')
            continue
        pubs[conn.topic].publish(bytes(raw))
        sent[remap.get(conn.topic, conn.topic)] += 1
    unread = reader.unread(read) if window is None else None
    if unread is not None:
        pace.wait_until(pace.now() + round(LINGER_S * 1e9 * rate))  # the last messages leave
        raise unread


def _publishers(node: Node, bag: str, connections: Sequence[Connection], *, topics: Sequence[str] | None,
                remap: dict[str, str], reliable: bool | None, depth: int, overrides: Mapping[str, QoSProfile]
                ) -> dict[str, Publisher]:
    """A publisher per topic played (``topics``, else every one), with its override, else the QoS
    forced, else its recorded one."""
    forced = None if reliable is None else QoSProfile(
        depth=depth, reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT)
    conns = [c for c in connections if topics is None or c.topic in topics]
    missing = sorted(set(topics or ()) - {c.topic for c in conns})
    if missing:
        raise BagError(f'{bag}: no topic {", ".join(missing)}')
    for topic in sorted(set(overrides) - {c.topic for c in conns}):
        node.get_logger().warning(f'a QoS override names {topic}, which is not a topic played from {bag}')
    return {c.topic: node.create_publisher(message_class(c.msgtype), remap.get(c.topic, c.topic),
                                           overrides.get(c.topic) or forced or recorded_qos(c, depth=depth))
            for c in conns}


_POLICIES: dict[str, Any] = {'history': HistoryPolicy, 'reliability': ReliabilityPolicy,
                             'durability': DurabilityPolicy, 'liveliness': LivelinessPolicy}
"""The QoS policies a profile names by their short keys (keep_last, best_effort, transient_local, ...)."""
_DURATIONS = ('deadline', 'lifespan', 'liveliness_lease_duration')
_VALUES = ('depth', 'avoid_ros_namespace_conventions')


def load_qos_overrides(path: str | Path) -> dict[str, QoSProfile]:
    """{topic: QoS} from a YAML file of ``ros2 bag play --qos-profile-overrides-path``'s format: each
    topic a mapping of history, depth, reliability, durability, liveliness (their short keys),
    deadline, lifespan, liveliness_lease_duration ({sec, nsec}) and avoid_ros_namespace_conventions;
    what a policy leaves out, rclpy's default. ParameterError naming the file, the topic and the key."""
    try:
        doc = YAML(typ='safe').load(Path(path).read_text())
    except (OSError, YAMLError) as exc:
        raise ParameterError(f'{path}: cannot read QoS overrides ({exc})') from exc
    if not isinstance(doc, dict):
        raise ParameterError(f'{path}: QoS overrides are a mapping of topic to profile, got {type(doc).__name__}')
    return {str(topic): _profile(profile, where=f'{path}: {topic}') for topic, profile in doc.items()}


def _profile(policies: object, *, where: str) -> QoSProfile:
    if not isinstance(policies, dict):
        raise ParameterError(f'{where}: a profile is a mapping of policy to value, got {policies!r}')
    kwargs: dict[str, Any] = {}
    for key, value in policies.items():
        if key not in (*_POLICIES, *_DURATIONS, *_VALUES):
            raise ParameterError(f'{where}: unknown QoS policy {key!r} (one of '
                                 f'{", ".join([*_POLICIES, *_DURATIONS, *_VALUES])})')
        try:
            if key in _POLICIES:
                kwargs[key] = _POLICIES[key].get_from_short_key(str(value))
            elif key in _DURATIONS:
                kwargs[key] = Duration(seconds=int(value['sec']), nanoseconds=int(value['nsec']))
                if kwargs[key] < Duration():
                    raise ValueError('a duration may not be negative')
            else:
                if key == 'depth' and (type(value) is not int or value < 0):
                    raise ValueError('depth is a whole number >= 0')
                kwargs[key] = value
        except (KeyError, TypeError, ValueError) as exc:
            raise ParameterError(f'{where}: {key}: {value!r} is not a value of it ({exc})') from exc
    try:
        return QoSProfile(**kwargs)
    except InvalidQoSProfileException as exc:
        raise ParameterError(f'{where}: {exc}') from exc


def _wait_subscribers(bag: str, pubs: dict[str, Publisher], n: int, *, timeout_s: float, pace: Pace) -> None:
    """Until the topics played that someone subscribes to have ``n`` subscribers each (a topic
    nobody subscribes to is not waited for), and have stayed so for ``SETTLE_S``."""
    deadline = time.monotonic() + timeout_s
    ready_since: float | None = None
    ready: set[str] = set()
    while True:
        counts = {t: p.get_subscription_count() for t, p in pubs.items()}
        now_ready = {t for t, c in counts.items() if c >= n}
        settled = bool(now_ready) and now_ready == {t for t, c in counts.items() if c}
        if not settled or now_ready != ready:
            ready_since = time.monotonic() if settled else None
            ready = now_ready
        if ready_since is not None and time.monotonic() - ready_since >= SETTLE_S:
            return
        if time.monotonic() > deadline:
            short = ', '.join(f'{t} ({c})' for t, c in counts.items() if c and c < n)
            raise BagError(f'{bag}: ' + (f'fewer than {n} subscribers on {short}' if short else
                                         'nobody subscribes to any topic played')
                           + f' after {timeout_s:g} s')
        pace.tick()
        if pace.stop.wait(0.02):
            raise KeyboardInterrupt


def _wait_resumed(service: _ResumeService, pace: Pace) -> None:
    """Until the player's ``~/resume`` service is called (``start_paused``), /clock held meanwhile.
    ExternalShutdownException when the context is shut down meanwhile."""
    while not service.resumed.wait(0.02):
        pace.tick()
        service.check()
        if pace.stop.is_set():
            raise KeyboardInterrupt


class _ResumeService:
    """The player's ``~/resume`` service (std_srvs/Trigger), set when called, answered from a thread of
    its own for as long as the player plays: a caller whose first reply was lost (a reply sent before
    the caller's reader matched) asks again, and is answered while the bag plays."""

    def __init__(self, node: Node) -> None:
        self.resumed = threading.Event()
        self.error: Exception | None = None
        """What stopped the thread: the context shut down from outside (``check`` raises it)."""
        node.create_service(Trigger, '~/resume', self._resume)
        self._executor = SingleThreadedExecutor(context=node.context)
        self._executor.add_node(node)
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._spin, name='evsync-player-resume', daemon=True)

    def _resume(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.resumed.set()
        response.success, response.message = True, 'playing'
        return response

    def _spin(self) -> None:
        try:
            while not self._done.is_set():
                self._executor.spin_once(timeout_sec=0.1)
        except (ExternalShutdownException, ShutdownException) as exc:
            self.error = exc

    def check(self) -> None:
        if self.error is not None:
            raise self.error

    def __enter__(self) -> _ResumeService:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._done.set()
        self._thread.join(timeout=5.0)
        self._executor.shutdown()


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
