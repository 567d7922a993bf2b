"""The message path shared by ``evsync_node`` and its camera processes: each event message decoded,
counted and restamped with its camera's correction (or what ``before_lock`` says before the lock),
companions restamped with their camera, held messages released; and the node parameters declared
as rclpy sees them. A subclass says where a camera's events go (``_feed``) and where its correction
comes from (``_correction``, ``_coarse``, ``_passthrough``)."""

from __future__ import annotations

import struct
import threading
import time
from collections.abc import Callable
from types import FrameType
from typing import Any

import rclpy
import rclpy.executors
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.duration import Duration
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterUninitializedException,
)
from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.density import TimeArray
from evsync_ros.errors import ParameterError
from evsync_ros.ros.diagnostics import LATENCY_SAMPLES, CompanionState, StreamState
from evsync_ros.ros.parameters import NODE_PARAMETERS, RUNTIME, NodeConfig, expected, node_config, node_defaults
from msg_adapters.header import restamp_header
from msg_adapters.registry import camera_model

_KINDS = {'string': ParameterType.PARAMETER_STRING, 'string_array': ParameterType.PARAMETER_STRING_ARRAY,
          'double': ParameterType.PARAMETER_DOUBLE, 'double_array': ParameterType.PARAMETER_DOUBLE_ARRAY,
          'integer': ParameterType.PARAMETER_INTEGER}
UNSHIFTED = ClockCorrection(offset_ns=0)
BURST_WAIT_S = 2.0
"""How long a backlog going out at once waits in all, a half history at a time, for its subscribers'
acknowledgements (a subscriber that never acknowledges stalls the node no longer than this)."""
"""What a camera's messages get before its lock (forwarded, or held too long). They still pass through
its restamper, which must see every message in order: an evt3 consumer anchors sensor time on the
first message it gets, so the restamper's output anchor has to be that same message's (a lock that
only moved header.stamp afterwards would never reach the events)."""


def declare_parameters(node: Node) -> NodeConfig:
    """Declare every node parameter on ``node`` (read only, typed, ranged) and return the checked
    configuration; ParameterError names the parameter that does not check out."""
    defaults = node_defaults()
    for name, spec in NODE_PARAMETERS.items():
        descriptor = ParameterDescriptor(description=spec.description, type=_KINDS[spec.kind],
                                         read_only=name not in RUNTIME)
        if spec.kind in ('double', 'double_array'):
            descriptor.floating_point_range = [FloatingPointRange(from_value=spec.low, to_value=spec.high)]
        elif spec.kind == 'integer' and spec.low is not None and spec.high is not None:
            descriptor.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high))]
        if spec.choices:
            descriptor.additional_constraints = f'one of: {", ".join(spec.choices)}'
        try:  # an optional parameter left out (an empty array): declared by its type alone
            default = defaults[name] if defaults[name] is not None else Parameter.Type.STRING_ARRAY
            node.declare_parameter(name, default, descriptor)
        except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
            # rclpy's own check of a --ros-args or params-file value: say it as the others are said
            whole = (' (write whole numbers as decimals: 1.0, not 1)'
                     if 'double' in spec.kind and isinstance(exc, InvalidParameterTypeException) else '')
            raise ParameterError(f'node {node.get_fully_qualified_name()}: {name} must be '
                                 f'{expected(spec)}{whole}: {exc}') from exc
    values = {name: parameter_value(node, name) for name in NODE_PARAMETERS}
    return node_config(values, source=f'node {node.get_fully_qualified_name()}')


def parameter_value(node: Node, name: str) -> Any:
    """A parameter's value (None: an optional one left out)."""
    try:
        return node.get_parameter(name).value
    except ParameterUninitializedException:
        return None


def ros_now(node: Node) -> Callable[[], int]:
    """The node's ROS clock in ns, as rclpy's timers see it: with ``use_sim_time`` the newest /clock
    (0 before the first), else the system clock, which is then read directly (what rclpy's
    ``Clock.now()`` returns, at well under a tenth of its cost per message: 23 us against 0.1 us on
    the loaded 2-core host)."""
    clock = node.get_clock()
    sim = [bool(node.get_parameter('use_sim_time').value)]

    def follow(params: list[Parameter]) -> None:
        for p in params:
            if p.name == 'use_sim_time':
                sim[0] = bool(p.value)

    node.add_post_set_parameters_callback(follow)
    return lambda: clock.now().nanoseconds if sim[0] else time.time_ns()


def events_qos(config: NodeConfig) -> QoSProfile:
    """The QoS of event inputs and outputs (``qos``, ``qos_depth``)."""
    if config.qos == 'sensor_data':
        return QoSProfile(depth=config.qos_depth, reliability=qos_profile_sensor_data.reliability,
                          history=HistoryPolicy.KEEP_LAST, durability=qos_profile_sensor_data.durability)
    return QoSProfile(depth=config.qos_depth, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)


def output_qos(config: NodeConfig) -> QoSProfile:
    """The QoS of the restamped event outputs: the events' (``qos``, ``qos_depth``), reliable when
    ``output_reliability`` or ``qos`` says so, else best effort."""
    reliable = config.output_reliability == 'reliable' or config.qos == 'reliable'
    return QoSProfile(depth=config.qos_depth, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=qos_profile_sensor_data.durability)


def companion_qos(node: Node, topic: str, events: QoSProfile, depth: int) -> tuple[QoSProfile, QoSProfile]:
    """(subscription, republisher) QoS of a companion: as its publisher offers it (reliability and
    durability: a transient-local camera_info stays so for late subscribers) when one is up as
    the node starts; else taken as the events are, offered reliable (which serves best-effort
    subscribers too)."""
    infos = node.get_publishers_info_by_topic(topic)
    if infos:
        offered = infos[0].qos_profile
        same = QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST,
                          reliability=offered.reliability, durability=offered.durability)
        return same, same
    return events, QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)


class MessagePath:
    """The message path of a node that republishes event streams (module notes). The node sets
    ``config``, ``streams``, ``companions``, the clocks and ``_host_stamped = {}``."""

    config: NodeConfig
    streams: dict[str, StreamState]
    companions: dict[str, CompanionState]
    _arrival_clock: Callable[[], int]
    _host_clock: Callable[[], int]
    _host_stamped: dict[str, bool]

    def _feed(self, st: StreamState, times: TimeArray, receipt: int, raw: bytes) -> None:
        """Give a message's event times to the estimate (``receipt``: when it arrived)."""
        raise NotImplementedError

    def _modelled(self, st: StreamState) -> None:
        """The stream's camera model is known (its first decoded message): none of its business here."""

    def _correction(self, topic: str) -> ClockCorrection | None:
        """The correction a camera's messages get now (None: not locked)."""
        raise NotImplementedError

    def _coarse(self, st: StreamState) -> ClockCorrection | None:
        """The correction of ``before_lock: coarse``: the offset seen in arrival times (None while
        the reference has sent nothing)."""
        raise NotImplementedError

    def _passthrough(self, topic: str) -> bool:
        """Whether a camera's messages go out with no correction (the reference, unless the rig is on
        host time); they still pass its restamper, for the stamp rule (docs/messages.md)."""
        raise NotImplementedError

    def _host_pair(self, topic: str, times: TimeArray, raw: bytes) -> tuple[int, int]:
        """``reference: host``: when the host had this message, as (event time, host time): its
        header.stamp against its first event where the driver stamps with the host clock (within 1 s
        of it at the stream's first message), else now against its last event."""
        now = self._host_clock()
        stamp = _stamp_ns(raw[4:12])
        stamped = self._host_stamped.setdefault(topic, abs(stamp - now) < 1_000_000_000)
        return (int(times[0]), stamp) if stamped else (int(times[-1]), now)

    def _on_message(self, st: StreamState, raw: bytes) -> None:
        start = time.perf_counter_ns()
        receipt = self._arrival_clock()
        st.received += 1
        if st.seen(raw):
            st.duplicates += 1  # each message goes out once: a second delivery is counted, not republished
            return
        stamp = raw[4:12]
        if len(stamp) == 8 and st.last_stamp and _stamp_ns(stamp) < _stamp_ns(st.last_stamp):
            st.out_of_order += 1
        st.last_stamp = stamp
        try:
            if st.model or not st.msgtype:  # the estimate's decode (``bag.estimate``): times alone
                times, view = st.decoder.decode_times(raw), None
            else:  # its first message: what camera it is, from its fields
                view, events = st.decoder.decode(raw)
                times = events.t
        except Exception as exc:  # noqa: BLE001 (whatever the bytes, the message is counted and goes on)
            st.malformed += 1
            st.last_error = f'message {st.received}: {exc}'
            self._publish(st, raw, start)  # unchanged: counted, not dropped
            return
        if times.size:
            st.last_time_ns = int(times[-1])
            st.times.add(times, receipt)
        if view is not None:
            st.model = camera_model(st.msgtype, view)
            self._modelled(st)
        self._feed(st, times, receipt, raw)
        if st.publisher is None:  # republish none: the estimate is all this message was for
            return
        if self._passthrough(st.topic):  # the rig's timeline: no correction, but the one stamp rule
            self._restamp_and_publish(st, raw, UNSHIFTED, start)
            return
        correction = self._correction(st.topic)
        if correction is None:
            self._before_lock(st, raw, receipt, start)
            return
        if st.held:
            self._flush(st, correction)
        self._restamp_and_publish(st, raw, correction, start)

    def _warn(self, text: str) -> None:
        """A warning in the node's log."""
        logger = getattr(self, 'get_logger', None)
        if logger is not None:
            logger().warning(text)

    def _on_companion(self, cs: CompanionState, raw: bytes) -> None:
        """A companion's message: its camera's correction now, or what its camera's messages get
        before the lock (held with ``hold`` until the lock, or the hold limit)."""
        receipt = self._arrival_clock()
        cs.received += 1
        off = cs.stamps.check(_stamp_ns(raw[4:12]), receipt, self.streams[cs.camera].times) if len(raw) >= 12 else None
        if off is not None and cs.stamps.disagreeing == 1:  # said once here; /diagnostics keeps saying it
            self._warn(cs.stamps.says())
        correction = self._companion_correction(cs)
        if correction is None:
            cs.held.append((receipt, raw))
            self._release_companion(cs, receipt)
            return
        if cs.held:
            self._flush_companion(cs, correction)
        self._publish_companion(cs, raw, correction)

    def _companion_correction(self, cs: CompanionState) -> ClockCorrection | None:
        """What a companion's message gets now (None: held)."""
        if self._passthrough(cs.camera):
            return UNSHIFTED
        correction = self._correction(cs.camera)
        if correction is not None:
            return correction
        if self.config.before_lock == 'forward':
            return UNSHIFTED
        if self.config.before_lock == 'coarse':
            return self._coarse(self.streams[cs.camera])
        return None

    def _publish_companion(self, cs: CompanionState, raw: bytes, correction: ClockCorrection) -> None:
        try:
            out = restamp_header(raw, correction, what=f'message {cs.received} of {cs.topic}')
            cs.applied = correction
        except Exception as exc:  # noqa: BLE001 (counted and published unchanged, as event messages are)
            cs.malformed += 1
            cs.last_error = str(exc)
            out = raw
        cs.publisher.publish(out)
        cs.published += 1

    def _release_companion(self, cs: CompanionState, now: int | None) -> None:
        while cs.held and (now is None or now - cs.held[0][0] > self.config.hold_limit_ns):
            _, raw = cs.held.popleft()
            cs.released_unshifted += 1
            self._publish_companion(cs, raw, UNSHIFTED)

    def _flush_companion(self, cs: CompanionState, correction: ClockCorrection) -> None:
        sent, until = 0, time.monotonic() + BURST_WAIT_S
        while cs.held:
            _, raw = cs.held.popleft()
            self._publish_companion(cs, raw, correction)
            sent = self._paced(cs.publisher, sent, until)

    def _paced(self, publisher: Any, sent: int, until: float) -> int:
        """Count a message of a backlog going out at once (held until the lock); every half of the
        output's history, wait until its subscribers have acknowledged it all, while ``until``
        (monotonic s) has not passed: a reliable output keeps only the last ``qos_depth`` messages,
        and a burst larger than that would overwrite what a slower subscriber has not yet taken.
        Best effort returns at once."""
        sent += 1
        left = until - time.monotonic()
        if publisher is not None and left > 0 and sent % max(1, self.config.qos_depth // 2) == 0:
            publisher.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9)))
        return sent

    def _before_lock(self, st: StreamState, raw: bytes, receipt: int, start: int) -> None:
        mode = self.config.before_lock
        if mode == 'coarse':
            coarse = self._coarse(st)
            if coarse is None:  # the arrival offset needs a message of the reference: held until then
                st.held.append((receipt, raw))
                self._release_overdue(st, receipt)
                return
            if st.held:
                self._flush(st, coarse)
            self._restamp_and_publish(st, raw, coarse, start)
            return
        if mode == 'hold':
            st.held.append((receipt, raw))
            self._release_overdue(st, receipt)
            return
        self._restamp_and_publish(st, raw, UNSHIFTED, start)

    def _release_overdue(self, st: StreamState, now: int | None) -> None:
        """Held messages older than hold_limit (None: every one) go out unshifted."""
        while st.held and (now is None or now - st.held[0][0] > self.config.hold_limit_ns):
            _, raw = st.held.popleft()
            st.released_unshifted += 1
            self._restamp_and_publish(st, raw, UNSHIFTED, None)

    def _flush(self, st: StreamState, correction: ClockCorrection) -> None:
        sent, until = 0, time.monotonic() + BURST_WAIT_S
        while st.held:
            _, raw = st.held.popleft()
            self._restamp_and_publish(st, raw, correction, None)
            sent = self._paced(st.publisher, sent, until)

    def _restamp_and_publish(self, st: StreamState, raw: bytes, correction: ClockCorrection, start: int | None) -> None:
        try:
            out = bytes(st.restamper.restamp(raw, correction))
        except Exception as exc:  # noqa: BLE001 (as above)
            st.unrestamped += 1
            st.last_error = f'message {st.received}: cannot restamp: {exc}'
            out = raw
        self._publish(st, out, start)

    def _publish(self, st: StreamState, raw: bytes, start: int | None) -> None:
        if st.publisher is None:  # republish none
            return
        st.publisher.publish(raw)
        st.published += 1
        if start is not None:
            st.latency_ns[st.latency_count % LATENCY_SAMPLES] = time.perf_counter_ns() - start
            st.latency_count += 1

    def _release_held(self, now: int) -> None:
        """Held messages go out with their camera's lock (or the coarse offset), else past the hold limit."""
        for st in self.streams.values():
            if not st.held:
                continue
            correction = self._correction(st.topic)
            if correction is None and self.config.before_lock == 'coarse':
                correction = self._coarse(st)
            if correction is not None:
                self._flush(st, correction)
            else:
                self._release_overdue(st, now)
        for cs in self.companions.values():
            if cs.held:
                correction = self._companion_correction(cs)
                if correction is not None:
                    self._flush_companion(cs, correction)
                else:
                    self._release_companion(cs, now)

    def flush_held(self) -> int:
        """Publish every held message (on shutdown: nothing is lost): restamped when its camera is
        locked, else unshifted and counted. Returns how many went out."""
        n = 0
        for st in self.streams.values():
            correction = self._correction(st.topic)
            n += len(st.held)
            if correction is not None:
                self._flush(st, correction)
            else:
                self._release_overdue(st, None)
        for cs in self.companions.values():
            n += len(cs.held)
            correction = self._companion_correction(cs)
            if correction is not None:
                self._flush_companion(cs, correction)
            else:
                self._release_companion(cs, None)
        return n


def _stamp_ns(stamp: bytes) -> int:
    sec, nanosec = struct.unpack('<iI', stamp)
    return sec * 1_000_000_000 + nanosec


STOP = threading.Event()
"""Set by SIGINT or SIGTERM (``interrupt``): the spin returns, and the node shuts down as ``main`` says."""


def spin(node: Node, *, executor: str) -> None:
    """Take ``node``'s callbacks until its context shuts down or SIGINT or SIGTERM (``interrupt``)
    stops it. ``events``: rclpy's EventsExecutor, whose C++ dispatch costs a third of
    ``rclpy.spin``'s per message (bench/node.py, relay rows); else a SingleThreadedExecutor. Both
    are driven by ``spin_once``, which lets the GIL go while it waits (the EventsExecutor's
    ``spin()``, rclpy 7.1.5, never returned here and kept signals from being handled), and which
    leaves a signal to be seen between callbacks, never inside one."""
    events = _events_executor(node) if executor == 'events' else None
    if events is None:
        if executor == 'events':
            node.get_logger().warning('executor events: this rclpy has no EventsExecutor; spinning with rclpy.spin')
        node.get_logger().info('executor: rclpy.spin')
        chosen: Executor = rclpy.executors.SingleThreadedExecutor(context=node.context)
    else:
        node.get_logger().info("executor: rclpy's EventsExecutor")
        chosen = events
    chosen.add_node(node)
    try:
        while node.context.ok() and not STOP.is_set():
            chosen.spin_once(timeout_sec=0.1)
    finally:
        chosen.shutdown()


def _events_executor(node: Node) -> Executor | None:
    """rclpy's EventsExecutor for ``node``'s context, or None where this rclpy has none."""
    try:
        from rclpy.experimental.events_executor import EventsExecutor
    except ImportError:
        return None
    return EventsExecutor(context=node.context)


def interrupt(signum: int, frame: FrameType | None) -> None:
    """SIGINT and SIGTERM: the spin stops after the callback under way, and what is held can still go
    out (``STOP``); a second one, while the node shuts down, stops it there (KeyboardInterrupt)."""
    if STOP.is_set():
        raise KeyboardInterrupt
    STOP.set()
