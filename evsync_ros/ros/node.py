"""evsync_node: synchronise event cameras online and republish every stream on the reference's timeline.
What it subscribes to and publishes, and its parameters: docs/node.md."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import gc
import json
import signal
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import rclpy
import rclpy.utilities
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import TimeReference
from std_msgs.msg import Float64, Int64MultiArray, String
from std_srvs.srv import SetBool, Trigger

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.density import TimeArray
from evsync_ros.core.engine import Engine, State
from evsync_ros.core.errors import StreamError
from evsync_ros.core.host import HostFit, HostTracker
from evsync_ros.core.runner import Runner
from evsync_ros.errors import EXPECTED_ERRORS, ParameterError
from evsync_ros.ros import camera, operations
from evsync_ros.ros.diagnostics import (
    CompanionState,
    StreamState,
    companion_diagnostic,
    estimator_restarted,
    host_diagnostic,
    messages_lost,
    stream_diagnostic,
    time_msg,
)
from evsync_ros.ros.messages import companion_class, message_class
from evsync_ros.ros.parameters import NodeConfig, checked_value
from evsync_ros.ros.path import (
    MessagePath,
    companion_qos,
    declare_parameters,
    events_qos,
    interrupt,
    output_qos,
    ros_now,
    spin,
)
from evsync_ros.ros.status import NAMES as STATUS_NAMES
from evsync_ros.ros.status import camera_values, field_topic
from evsync_ros.runtime.runner import runner
from evsync_ros.runtime.wire import unpack
from msg_adapters.registry import Restamper, decoder_for

CLOCK_WAIT_S = 5.0
"""With ``use_sim_time``: how long the node waits for a first /clock before it warns."""


class EvsyncNode(MessagePath, Node):
    """The live synchronisation node (module notes)."""

    def __init__(self, *, clock: Callable[[], int] | None = None, host_clock: Callable[[], int] | None = None,
                 **kwargs: Any) -> None:
        """``clock``: when messages arrive, in ns; ``host_clock``: the host's time, what ``reference:
        host`` puts the rig on. Both are the node's ROS clock (``use_sim_time`` with /clock: the
        clock's time) unless given (tests replay recorded arrival times)."""
        super().__init__('evsync', **kwargs)
        now = ros_now(self)
        self._arrival_clock = clock or now
        self._host_clock = host_clock or now
        self.config: NodeConfig = declare_parameters(self)
        cfg = self.config
        self.sync = Engine(cfg.topics, reference=cfg.reference, params=cfg.online, latencies_ns=cfg.latencies_ns)
        self.host = HostTracker(span_ns=cfg.online.drift_span_ns, floor_ns=cfg.host_floor_ns) if cfg.host else None
        """reference host: the cameras' common timeline onto host time (None: a camera is the reference)."""
        self.host_fit: HostFit | None = None
        self.host_error = ''
        self._host_stamped: dict[str, bool] = {}
        self._started_ns: int | None = None
        """When the node's clock first ran (on sim time: the first /clock, not 0)."""
        self.started_ns(self._arrival_clock())
        qos = events_qos(cfg)
        self.streams: dict[str, StreamState] = {}
        self.companions: dict[str, CompanionState] = {}
        self.remote: dict[str, dict[str, Any]] = {}
        """per_camera: each stream's message path as its camera process last reported it."""
        self.bad_batches = 0
        self.processes: dict[str, subprocess.Popen[bytes]] = {}
        """per_camera: each stream's camera process (started by ``main``)."""
        for topic, msgtype, output in zip(cfg.topics, cfg.types, cfg.outputs):
            st = StreamState(topic, output, decoder_for(msgtype), Restamper(msgtype, live=True), msgtype=msgtype)
            self.streams[topic] = st
            if cfg.processes == 'one':
                cls = message_class(msgtype)
                if cfg.republish == 'all':
                    st.publisher = self.create_publisher(cls, output, output_qos(cfg))
                st.subscription = self.create_subscription(cls, topic, functools.partial(self._on_message, st), qos,
                                                           raw=True)
        for comp in cfg.companions if cfg.republish == 'all' else ():  # none: nothing of theirs to do
            cls = companion_class(comp.topic, comp.msgtype)  # a type without a Header stops the node here
            cs = CompanionState(comp.topic, comp.camera, comp.output)
            self.companions[comp.topic] = cs
            if cfg.processes == 'one':
                take, offer = companion_qos(self, comp.topic, qos, cfg.qos_depth)
                cs.publisher = self.create_publisher(cls, comp.output, offer)
                cs.subscription = self.create_subscription(cls, comp.topic, functools.partial(self._on_companion, cs),
                                                           take, raw=True)
        if cfg.processes == 'per_camera':
            base = self.get_fully_qualified_name()
            self.counts_source = camera.counts_topic(base)
            self.create_subscription(Int64MultiArray, camera.counts_topic(base), self._on_counts,
                                     camera.CHANNEL_QOS)
            self.create_subscription(String, camera.state_topic(base), self._on_camera_state, camera.CHANNEL_QOS)
            self.corrections_pub = self.create_publisher(String, camera.corrections_topic(base),
                                                         camera.CORRECTIONS_QOS)
        self.offsets_pub = self.create_publisher(TimeReference, cfg.offsets_topic, 10)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.status_pubs: dict[str, dict[str, Any]] = {
            topic: {name: self.create_publisher(Float64, field_topic(cfg.status_topic, topic, name), 10)
                    for name in STATUS_NAMES}
            for topic in (cfg.topics if cfg.status_topic else ())}
        """Per camera, per quantity of ``ros.status.FIELDS``: its std_msgs/Float64 publisher."""
        self._wake = threading.Event()
        self._stop = threading.Event()
        self.worker_error: BaseException | None = None
        self.estimator_restarts = 0
        """Times the estimator process died and was started again (warned of in the log and /diagnostics)."""
        self._worker = threading.Thread(target=self._work, name='evsync-estimator', daemon=True)
        self._worker.start()
        self.create_timer(cfg.estimate_period_ns / 1e9, self._on_estimate_timer)
        self._report_timer = self.create_timer(cfg.diagnostics_period_ns / 1e9, self._on_report_timer)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        if self.get_parameter('use_sim_time').value:  # its timers wait for /clock: say so if none comes
            self._clock_check = self.create_timer(CLOCK_WAIT_S, self._on_clock_check,
                                                  clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._seed()
        self.create_service(Trigger, '~/save_offsets', self._on_save_offsets)
        self.create_service(Trigger, '~/reacquire', self._on_reacquire)
        self.create_service(SetBool, '~/freeze', self._on_freeze)
        # the estimator's process starts last, once nothing else here can fail and leave it behind
        # (until then the sync fits in this thread)
        with _interrupt_ignored():  # Ctrl-C reaches the whole process group: the node stops the estimator
            self.sync.runner = runner(cfg.estimator, nice=cfg.estimator_nice)
        self.get_logger().info(
            f'synchronising {len(cfg.topics)} streams onto {cfg.reference} ({cfg.online.method}); '
            f'outputs {", ".join(cfg.outputs)}; before the lock: {cfg.before_lock}; {self.runner.where}')

    # -- where events go and corrections come from (the message path's hooks) -------------------

    def _feed(self, st: StreamState, times: TimeArray, receipt: int, raw: bytes) -> None:
        self.started_ns(receipt)
        if self.host is not None and times.size:
            self.host.add(st.topic, *self._host_pair(st.topic, times, raw))
        self.sync.add(st.topic, times, receipt)

    def _modelled(self, st: StreamState) -> None:
        self.sync.set_model(st.topic, st.model)  # another model than the reference's: more error, as offline

    def _correction(self, topic: str) -> ClockCorrection | None:
        """The correction a camera's messages get now: onto the reference camera's timeline, and with
        reference host onto the host clock (None: not locked, or the host line not fitted yet)."""
        c = self.sync.correction(topic)
        if self.host is None or c is None:
            return c
        fit = self.host_fit
        return None if fit is None else c.then(fit.correction)

    def _coarse(self, st: StreamState) -> ClockCorrection | None:
        prior = self._prior(st.topic)
        return None if prior is None else ClockCorrection(offset_ns=prior)

    def _prior(self, topic: str) -> int | None:
        """The offset seen in arrival times (onto the host clock with ``reference: host``)."""
        return self.sync.prior(topic) if self.host is None else self.host.prior(topic)

    def _passthrough(self, topic: str) -> bool:
        return topic == self.config.reference and self.host is None

    # -- operating: saved offsets and services (ros.operations) ------------------------------------

    def _seed(self) -> None:
        path = self.config.offsets_file
        if not path:
            return
        seeded = operations.seed_from_file(self.sync, path)  # ParameterError: exit 2, naming the file
        if seeded is None:
            self.get_logger().warning(f'offsets_file {path}: not there yet; estimating from scratch '
                                      '(~/save_offsets writes it)')
        else:
            self.get_logger().info(f'offsets_file {path}: seeded {", ".join(seeded) or "no camera"}')

    def _on_save_offsets(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        path = self.config.offsets_file
        if not path:
            response.success, response.message = False, 'offsets_file is not set: nowhere to save'
            return response
        try:
            n = operations.save_offsets(self.sync, path)
        except OSError as exc:
            response.success, response.message = False, f'{path}: {exc}'
            return response
        response.success, response.message = True, f'{n} cameras and the reference saved to {path}'
        self.get_logger().info(response.message)
        return response

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """``ros2 param set`` of a RUNTIME parameter (rclpy refuses the read-only ones): checked as at
        start, then in force from the next message, estimate or report."""
        source = f'node {self.get_fully_qualified_name()}'
        try:
            values = {p.name: checked_value(p.name, p.value, source=source) for p in params}
            if 'before_lock' in values and self.config.processes == 'per_camera':
                raise ParameterError('before_lock is set at start with processes per_camera (each camera '
                                     'process reads it once)')
            if 'min_confidence' in values:
                self.sync.retune(min_confidence=values['min_confidence'])
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if 'diagnostics_period_s' in values:
            period = round(values['diagnostics_period_s'] * 1e9)
            self._report_timer.timer_period_ns = period
            self.config = dataclasses.replace(self.config, diagnostics_period_ns=period)
        if 'before_lock' in values:
            self.config = dataclasses.replace(self.config, before_lock=values['before_lock'])
        self.get_logger().info(f'parameters set: {values}')
        return SetParametersResult(successful=True)

    def _on_clock_check(self) -> None:
        self._clock_check.cancel()
        if not self.get_clock().now().nanoseconds:
            self.get_logger().warning(f'use_sim_time is set and no /clock came in {CLOCK_WAIT_S:g} s: messages are '
                                      'republished, but nothing is estimated or reported until one comes (a bag '
                                      'player publishes it with --clock)')

    def _on_reacquire(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.sync.reacquire()
        response.success, response.message = True, 'every camera re-estimates from the events held'
        self.get_logger().info(response.message)
        return response

    def _on_freeze(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        self.sync.freeze(bool(request.data))
        response.success = True
        response.message = ('frozen: the corrections in force stay until ~/freeze false or ~/reacquire'
                            if request.data else 'estimating again')
        self.get_logger().info(response.message)
        return response

    # -- per_camera: counts in, corrections out ---------------------------------------------------

    def _on_counts(self, msg: Int64MultiArray) -> None:
        """A camera process's batch of messages, counted on the grid: into the estimate."""
        try:
            index, messages = unpack(np.frombuffer(msg.data, np.int64), source=self.counts_source)
            topic = self.config.topics[index]
        except (StreamError, IndexError) as exc:
            self.bad_batches += 1
            self.get_logger().error(f'{exc} ({self.bad_batches} batches left out so far)', throttle_duration_sec=5.0)
            return
        for m in messages:
            if self.host is not None and m.host_event_ns is not None and m.host_ns is not None:
                self.host.add(topic, m.host_event_ns, m.host_ns)
            self.sync.add_bins(topic, m)

    def _on_camera_state(self, msg: String) -> None:
        try:
            values = json.loads(msg.data)
            self.remote[values['topic']] = values
        except (ValueError, KeyError, TypeError) as exc:
            self.get_logger().error(f'a camera process sent a state that is not one: {exc}', throttle_duration_sec=5.0)

    def _publish_corrections(self) -> None:
        """per_camera: what each camera process's messages get now (``camera.Corrections``)."""
        out = {}
        for topic in self.config.topics:
            c = self._correction(topic)
            out[topic] = {'state': self.sync.state(topic).value, 'prior_ns': self._prior(topic),
                          'correction': None if c is None else
                          {'offset_ns': c.offset_ns, 'skew_ppm': c.skew_ppm, 'anchor_ns': c.anchor_ns}}
        self.corrections_pub.publish(String(data=json.dumps(out)))

    def _process_error(self, topic: str) -> str:
        proc = self.processes.get(topic)
        if proc is None or proc.poll() is None:
            return ''
        return f'its camera process exited with status {proc.returncode}; its messages are not republished'

    # -- estimation (timer, worker thread) ------------------------------------------------------

    def _on_estimate_timer(self) -> None:
        self._wake.set()
        self._release_held(self._arrival_clock())

    def _work(self) -> None:
        try:
            while not self._stop.is_set():
                self._wake.wait()
                self._wake.clear()
                if self._stop.is_set():
                    return
                self.estimate(self._arrival_clock())
        except BaseException as exc:  # noqa: BLE001 (reported in /diagnostics and the log, not lost)
            self.worker_error = exc
            self.get_logger().error(f'estimation stopped: {exc!r}')

    @property
    def runner(self) -> Runner:
        """Where the estimator fits windows and finds their agreement (``Engine.runner``)."""
        return self.sync.runner

    def estimate(self, now_ns: int) -> None:
        """One estimate at ``now_ns`` (arrival clock): every camera stepped (``Engine.step``), the
        host line, and per_camera's corrections sent. The estimation thread calls it on each wake; a
        replay in recorded time calls it instead."""
        self.sync.step(now_ns)
        if self.runner.restarts > self.estimator_restarts:  # the estimator process died, and was replaced
            self.estimator_restarts = self.runner.restarts
            self.get_logger().warning(f'{estimator_restarted(self.estimator_restarts)}; now {self.runner.where}')
        self._fit_host()
        if self.config.processes == 'per_camera':
            self._publish_corrections()

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

    def started_ns(self, now: int) -> int:
        """When the node's clock first ran: its first non-zero reading (``use_sim_time`` reads 0 until
        the first /clock)."""
        if self._started_ns is None and now:
            self._started_ns = now
        return now if self._started_ns is None else self._started_ns

    def _on_report_timer(self) -> None:
        now = self._arrival_clock()
        started = self.started_ns(now)
        stamp = self.get_clock().now().to_msg()
        array = DiagnosticArray()
        array.header.stamp = stamp
        for cs in self.companions.values():
            remote = self.remote.get(cs.camera, {}).get('companions', {}).get(cs.topic)
            array.status.append(companion_diagnostic(cs, self.sync.state(cs.camera), remote))
        for st in self.streams.values():
            status = self.sync.status(st.topic, now_ns=now)
            array.status.append(stream_diagnostic(
                st, status, now_ns=now, silent_start=now - started > self.config.online.window_ns,
                started_ns=started, worker_error=self.worker_error,
                envelope_latency_ns=self.sync.latency_delta_ns[st.topic], path=self.remote.get(st.topic),
                process_error=self._process_error(st.topic), estimator_restarts=self.estimator_restarts))
            c = status.correction if self.host is None else self._correction(st.topic)
            pubs = self.status_pubs.get(st.topic)
            if pubs:
                reported = self.remote.get(st.topic)
                lost = int(reported['messages_lost']) if reported else messages_lost(st.decoder)
                for name, value in camera_values(status, correction=c, last_time_ns=st.last_time_ns,
                                                 lost=lost).items():
                    pubs[name].publish(Float64(data=value))
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

    def stop_estimator(self) -> None:
        """Stop the estimation thread (on shutdown; a replay that steps the estimator itself, in
        recorded time, stops it so that nothing else steps it at the same time)."""
        self._stop.set()
        self._wake.set()
        self._worker.join(timeout=5.0)

    def destroy_node(self) -> None:
        self.stop_estimator()
        self.runner.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """The ``evsync_node`` entry point: spin the node until SIGINT or SIGTERM, publish what it holds,
    shut down; exit status 2 (the parameter named) when its parameters do not check out. With
    ``processes: per_camera`` it starts a camera process per topic and stops them as it stops."""
    sys.setswitchinterval(0.0005)  # the estimator thread yields the GIL to the message path often
    # SIGINT and SIGTERM stop the spin here, not rclpy's context, so held messages can still go out
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, interrupt)
    signal.signal(signal.SIGTERM, interrupt)
    node = None
    try:
        node = EvsyncNode()
        if node.config.processes == 'per_camera':
            with _interrupt_ignored():  # they stop when the node tells them (stop_processes), not on Ctrl-C
                node.processes = camera.start_processes(node, ros_args=_ros_args(args if args is not None
                                                                                 else sys.argv))
        # what the node holds from its start (rclpy, numpy, its own state) is never garbage: a full
        # collection that walks it stops the message path for 6-9 ms, more on a busy host (bench/gc_pause.py)
        gc.freeze()
        spin(node, executor=node.config.executor)
    except (KeyboardInterrupt, ExternalShutdownException):  # a second signal while it started or stopped
        pass
    except EXPECTED_ERRORS as exc:
        print(f'evsync_node: {exc}', file=sys.stderr)
        return 2
    finally:
        if node is not None:
            camera.stop_processes(node.processes)
            flushed = node.flush_held() if rclpy.utilities.ok() else 0
            if flushed:
                node.get_logger().info(f'shutting down: {flushed} held messages published')
            node.destroy_node()
        rclpy.utilities.try_shutdown()
    return 0


@contextlib.contextmanager
def _interrupt_ignored() -> Iterator[None]:
    """SIGINT ignored by the processes started meanwhile (an ignored signal stays so across exec, and
    Python then leaves it so): a Ctrl-C at the terminal reaches the whole process group, and the
    node's helpers are stopped by the node, in order, as it shuts down. Where this is not the main
    thread (a node built by a test's thread), nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _ros_args(argv: list[str]) -> list[str]:
    """The ROS arguments of a command line (after ``--ros-args``), which camera processes get too."""
    return argv[argv.index('--ros-args') + 1:] if '--ros-args' in argv else []


if __name__ == '__main__':
    sys.exit(main())
