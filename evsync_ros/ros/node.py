"""evsync_node: synchronise event cameras online and republish every stream on the reference's timeline.
What it subscribes to and publishes, and its parameters: docs/node.md."""

from __future__ import annotations

import functools
import signal
import struct
import sys
import threading
import time
from collections.abc import Callable
from types import FrameType
from typing import Any

import rclpy
import rclpy.utilities
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterUninitializedException,
)
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import TimeReference

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.errors import StreamError
from evsync_ros.core.host import HostFit, HostTracker
from evsync_ros.core.online import OnlineSync, State
from evsync_ros.errors import EXPECTED_ERRORS, ParameterError
from evsync_ros.ros.diagnostics import (
    LATENCY_SAMPLES,
    CompanionState,
    StreamState,
    companion_diagnostic,
    host_diagnostic,
    stream_diagnostic,
    time_msg,
)
from evsync_ros.ros.messages import companion_class, message_class
from evsync_ros.ros.parameters import NODE_PARAMETERS, NodeConfig, expected, node_config, node_defaults
from msg_adapters.header import restamp_header
from msg_adapters.registry import Restamper, decoder_for

_KINDS = {'string': ParameterType.PARAMETER_STRING, 'string_array': ParameterType.PARAMETER_STRING_ARRAY,
          'double': ParameterType.PARAMETER_DOUBLE, 'double_array': ParameterType.PARAMETER_DOUBLE_ARRAY,
          'integer': ParameterType.PARAMETER_INTEGER}
UNSHIFTED = ClockCorrection(offset_ns=0)
"""What a camera's messages get before its lock (forwarded, or held too long). They still pass through
its restamper, which must see every message in order: an evt3 consumer anchors sensor time on the
first message it gets, so the restamper's output anchor has to be that same message's (a lock that
only moved header.stamp afterwards would never reach the events)."""
class EvsyncNode(Node):
    """The live synchronisation node (module notes)."""

    def __init__(self, *, clock: Callable[[], int] = time.monotonic_ns, host_clock: Callable[[], int] = time.time_ns,
                 **kwargs: Any) -> None:
        """``clock``: the host's arrival clock in ns (monotonic; tests replay recorded arrival times);
        ``host_clock``: the host's (ROS) time, what ``reference: host`` puts the rig on."""
        super().__init__('evsync', **kwargs)
        self._arrival_clock = clock
        self._host_clock = host_clock
        defaults = node_defaults()
        for name, spec in NODE_PARAMETERS.items():
            descriptor = ParameterDescriptor(description=spec.description, type=_KINDS[spec.kind], read_only=True)
            if spec.kind in ('double', 'double_array'):
                descriptor.floating_point_range = [FloatingPointRange(from_value=spec.low, to_value=spec.high)]
            elif spec.kind == 'integer' and spec.low is not None and spec.high is not None:
                descriptor.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high))]
            if spec.choices:
                descriptor.additional_constraints = f'one of: {", ".join(spec.choices)}'
            try:  # an optional parameter left out (an empty array): declared by its type alone
                default = defaults[name] if defaults[name] is not None else Parameter.Type.STRING_ARRAY
                self.declare_parameter(name, default, descriptor)
            except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
                # rclpy's own check of a --ros-args or params-file value: say it as the others are said
                whole = (' (write whole numbers as decimals: 1.0, not 1)'
                         if 'double' in spec.kind and isinstance(exc, InvalidParameterTypeException) else '')
                raise ParameterError(f'node {self.get_fully_qualified_name()}: {name} must be '
                                     f'{expected(spec)}{whole}: {exc}') from exc
        values = {name: self._value(name) for name in NODE_PARAMETERS}
        self.config: NodeConfig = node_config(values, source=f'node {self.get_fully_qualified_name()}')
        cfg = self.config
        self.sync = OnlineSync(cfg.topics, reference=cfg.reference, params=cfg.online, latencies_ns=cfg.latencies_ns)
        self.host = HostTracker(span_ns=cfg.online.drift_span_ns, floor_ns=cfg.host_floor_ns) if cfg.host else None
        """reference host: the cameras' common timeline onto host time (None: a camera is the reference)."""
        self.host_fit: HostFit | None = None
        self.host_error = ''
        self._host_stamped: dict[str, bool] = {}
        self._started_ns = self._arrival_clock()
        if cfg.qos == 'sensor_data':
            qos = QoSProfile(depth=cfg.qos_depth, reliability=qos_profile_sensor_data.reliability,
                             history=HistoryPolicy.KEEP_LAST, durability=qos_profile_sensor_data.durability)
        else:
            qos = QoSProfile(depth=cfg.qos_depth, reliability=ReliabilityPolicy.RELIABLE,
                             history=HistoryPolicy.KEEP_LAST)
        self.streams: dict[str, StreamState] = {}
        for topic, msgtype, output in zip(cfg.topics, cfg.types, cfg.outputs):
            cls = message_class(msgtype)
            st = StreamState(topic, output, decoder_for(msgtype), Restamper(msgtype, live=True))
            st.publisher = self.create_publisher(cls, output, qos)
            self.streams[topic] = st
            self.create_subscription(cls, topic, functools.partial(self._on_message, st), qos, raw=True)
        self.companions: dict[str, CompanionState] = {}
        for comp in cfg.companions:
            cls = companion_class(comp.topic, comp.msgtype)
            take, offer = self._companion_qos(comp.topic, qos)
            cs = CompanionState(comp.topic, comp.camera, comp.output)
            cs.publisher = self.create_publisher(cls, comp.output, offer)
            self.companions[comp.topic] = cs
            self.create_subscription(cls, comp.topic, functools.partial(self._on_companion, cs), take, raw=True)
        self.offsets_pub = self.create_publisher(TimeReference, cfg.offsets_topic, 10)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._wake = threading.Event()
        self._stop = threading.Event()
        self.worker_error: BaseException | None = None
        self._worker = threading.Thread(target=self._work, name='evsync-estimator', daemon=True)
        self._worker.start()
        self.create_timer(cfg.estimate_period_ns / 1e9, self._on_estimate_timer)
        self.create_timer(cfg.diagnostics_period_ns / 1e9, self._on_report_timer)
        self.get_logger().info(
            f'synchronising {len(cfg.topics)} streams onto {cfg.reference} ({cfg.online.method}); '
            f'outputs {", ".join(cfg.outputs)}; before the lock: {cfg.before_lock}')

    def _companion_qos(self, topic: str, events: QoSProfile) -> tuple[QoSProfile, QoSProfile]:
        """(subscription, republisher) QoS of a companion: as its publisher offers it (reliability and
        durability: a transient-local camera_info stays so for late subscribers) when one is up as
        the node starts; else taken as the events are, offered reliable (which serves best-effort
        subscribers too)."""
        infos = self.get_publishers_info_by_topic(topic)
        if infos:
            offered = infos[0].qos_profile
            same = QoSProfile(depth=self.config.qos_depth, history=HistoryPolicy.KEEP_LAST,
                              reliability=offered.reliability, durability=offered.durability)
            return same, same
        return events, QoSProfile(depth=self.config.qos_depth, reliability=ReliabilityPolicy.RELIABLE,
                                  history=HistoryPolicy.KEEP_LAST)

    def _value(self, name: str) -> Any:
        """A parameter's value (None: an optional one left out)."""
        try:
            return self.get_parameter(name).value
        except ParameterUninitializedException:
            return None

    # -- the message path (subscription callbacks) ----------------------------------------------

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
            _, events = st.decoder.decode(raw)
        except Exception as exc:  # noqa: BLE001 (whatever the bytes, the message is counted and goes on)
            st.malformed += 1
            st.last_error = f'message {st.received}: {exc}'
            self._publish(st, raw, start)  # unchanged: counted, not dropped
            return
        times = events.t
        if times.size:
            st.last_time_ns = int(times[-1])
            if self.host is not None:
                self._host_arrival(st.topic, times, raw)
        self.sync.add(st.topic, times, receipt)
        if st.topic == self.config.reference and self.host is None:
            self._publish(st, raw, start)
            return
        correction = self._correction(st.topic)
        if correction is None:
            self._before_lock(st, raw, receipt, start)
            return
        if st.held:
            self._flush(st, correction)
        self._restamp_and_publish(st, raw, correction, start)

    def _host_arrival(self, topic: str, times: Any, raw: bytes) -> None:
        """When the host had this message: its header.stamp against its first event where the driver
        stamps with the host clock (within 1 s of it at the stream's first message), else now against
        its last event."""
        assert self.host is not None
        now = self._host_clock()
        stamp = _stamp_ns(raw[4:12])
        stamped = self._host_stamped.setdefault(topic, abs(stamp - now) < 1_000_000_000)
        if stamped:
            self.host.add(topic, int(times[0]), stamp)
        else:
            self.host.add(topic, int(times[-1]), now)

    def _correction(self, topic: str) -> ClockCorrection | None:
        """The correction a camera's messages get now: onto the reference camera's timeline, and with
        reference host onto the host clock (None: not locked, or the host line not fitted yet)."""
        c = self.sync.correction(topic)
        if self.host is None or c is None:
            return c
        fit = self.host_fit
        return None if fit is None else c.then(fit.correction)

    def _on_companion(self, cs: CompanionState, raw: bytes) -> None:
        """A companion's message: its camera's correction now, or what its camera's messages get
        before the lock (held with ``hold`` until the lock, or the hold limit)."""
        receipt = self._arrival_clock()
        cs.received += 1
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
        if cs.camera == self.config.reference and self.host is None:
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
        while cs.held:
            _, raw = cs.held.popleft()
            self._publish_companion(cs, raw, correction)

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

    def _coarse(self, st: StreamState) -> ClockCorrection | None:
        """The correction of ``before_lock: coarse``: the offset seen in arrival times (None while
        the reference has sent nothing)."""
        prior = self.sync.prior(st.topic) if self.host is None else self.host.prior(st.topic)
        return None if prior is None else ClockCorrection(offset_ns=prior)

    def _release_overdue(self, st: StreamState, now: int | None) -> None:
        """Held messages older than hold_limit (None: every one) go out unshifted."""
        while st.held and (now is None or now - st.held[0][0] > self.config.hold_limit_ns):
            _, raw = st.held.popleft()
            st.released_unshifted += 1
            self._restamp_and_publish(st, raw, UNSHIFTED, None)

    def _flush(self, st: StreamState, correction: ClockCorrection) -> None:
        while st.held:
            _, raw = st.held.popleft()
            self._restamp_and_publish(st, raw, correction, None)

    def _restamp_and_publish(self, st: StreamState, raw: bytes, correction: ClockCorrection, start: int | None) -> None:
        try:
            out = bytes(st.restamper.restamp(raw, correction))
        except Exception as exc:  # noqa: BLE001 (as above)
            st.unrestamped += 1
            st.last_error = f'message {st.received}: cannot restamp: {exc}'
            out = raw
        self._publish(st, out, start)

    def _publish(self, st: StreamState, raw: bytes, start: int | None) -> None:
        st.publisher.publish(raw)
        st.published += 1
        if start is not None:
            st.latency_ns[st.latency_count % LATENCY_SAMPLES] = time.perf_counter_ns() - start
            st.latency_count += 1

    # -- estimation (timer, worker thread) ------------------------------------------------------

    def _on_estimate_timer(self) -> None:
        self._wake.set()
        now = self._arrival_clock()
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

    def _work(self) -> None:
        try:
            while not self._stop.is_set():
                self._wake.wait()
                self._wake.clear()
                if self._stop.is_set():
                    return
                self.sync.step(self._arrival_clock())
                self._fit_host()
        except BaseException as exc:  # noqa: BLE001 (reported in /diagnostics and the log, not lost)
            self.worker_error = exc
            self.get_logger().error(f'estimation stopped: {exc!r}')

    def _fit_host(self) -> None:
        """reference host: the host line through every locked camera's least arrival lags."""
        if self.host is None:
            return
        locked = {t: c for t in self.config.topics
                  if self.sync.state(t) is State.LOCKED and (c := self.sync.correction(t)) is not None}
        try:
            self.host_fit = self.host.fit(locked)
            self.host_error = ''
        except StreamError as exc:
            self.host_error = str(exc)

    # -- reporting (timer) ----------------------------------------------------------------------

    def _on_report_timer(self) -> None:
        now = self._arrival_clock()
        stamp = self.get_clock().now().to_msg()
        array = DiagnosticArray()
        array.header.stamp = stamp
        for cs in self.companions.values():
            array.status.append(companion_diagnostic(cs, self.sync.state(cs.camera)))
        for st in self.streams.values():
            status = self.sync.status(st.topic, now_ns=now)
            array.status.append(stream_diagnostic(
                st, status, now_ns=now, silent_start=now - self._started_ns > self.config.online.window_ns,
                started_ns=self._started_ns, worker_error=self.worker_error,
                envelope_latency_ns=self.sync.latency_delta_ns[st.topic]))
            c = status.correction if self.host is None else self._correction(st.topic)
            if (st.topic != self.config.reference or self.host) and c is not None and st.last_time_ns is not None:
                # as sensor_msgs/TimeReference defines it: header.stamp the time on the rig's timeline
                # (the reference camera's, or the host's), time_ref the same instant on the camera's own clock
                ref = TimeReference()
                ref.header.stamp = time_msg(c.apply_one(st.last_time_ns))
                ref.time_ref = time_msg(st.last_time_ns)
                ref.source = st.topic
                self.offsets_pub.publish(ref)
        if self.host is not None:
            array.status.append(host_diagnostic(self.host_fit, self.host_error))
        self.diagnostics_pub.publish(array)

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

    def stop_estimator(self) -> None:
        """Stop the estimation thread (on shutdown; a replay that steps the estimator itself, in
        recorded time, stops it so that nothing else steps it at the same time)."""
        self._stop.set()
        self._wake.set()
        self._worker.join(timeout=5.0)

    def destroy_node(self) -> None:
        self.stop_estimator()
        super().destroy_node()


def _stamp_ns(stamp: bytes) -> int:
    sec, nanosec = struct.unpack('<iI', stamp)
    return sec * 1_000_000_000 + nanosec


def main(args: list[str] | None = None) -> int:
    """The ``evsync_node`` entry point: spin the node until SIGINT or SIGTERM, publish what it holds,
    shut down; exit status 2 (the parameter named) when its parameters do not check out."""
    sys.setswitchinterval(0.0005)  # the estimator thread yields the GIL to the message path often
    # SIGINT and SIGTERM stop the spin here, not rclpy's context, so held messages can still go out
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGTERM, _interrupt)
    node = None
    try:
        node = EvsyncNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except EXPECTED_ERRORS as exc:
        print(f'evsync_node: {exc}', file=sys.stderr)
        return 2
    finally:
        if node is not None:
            flushed = node.flush_held() if rclpy.utilities.ok() else 0
            if flushed:
                node.get_logger().info(f'shutting down: {flushed} held messages published')
            node.destroy_node()
        rclpy.utilities.try_shutdown()
    return 0


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


if __name__ == '__main__':
    sys.exit(main())
