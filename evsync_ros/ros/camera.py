"""A camera process of ``evsync_node`` with ``processes: per_camera``: one camera's message path (its
events and companions decoded, restamped, republished) in a process of its own, so that the message
work of several cameras at 1 kHz spreads over cores (and, DDS carrying the topics, over hosts).

``evsync_node`` starts one per topic (``start_processes``) with its own parameters and ROS arguments,
and stops them as it stops. Each sends the estimator, in ``evsync_node``'s process, its messages as
counts on the estimator's grid (``core.counts``) every ``COUNTS_PERIOD_NS`` on ``<node>/_counts``, and
its message path's counters (and its companions') every diagnostics period on
``<node>/_camera_state``, which ``evsync_node`` reports in /diagnostics as its own; it restamps with
what the estimator publishes on ``<node>/_corrections`` (latched). These three topics are hidden
(their names begin with ``_``) and internal: their form may change between versions.
"""

from __future__ import annotations

import array
import contextlib
import functools
import gc
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import rclpy
import rclpy.utilities
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Int64MultiArray, String

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.counts import MessageBins
from evsync_ros.core.density import TimeArray
from evsync_ros.core.online import State
from evsync_ros.errors import EXPECTED_ERRORS, ParameterError
from evsync_ros.lifetime import die_with_parent
from evsync_ros.ros.diagnostics import CompanionState, StreamState, companion_values, path_values
from evsync_ros.ros.messages import companion_class, message_class
from evsync_ros.ros.parameters import NODE_PARAMETERS
from evsync_ros.ros.path import (
    MessagePath,
    companion_qos,
    declare_parameters,
    events_qos,
    interrupt,
    output_qos,
    parameter_value,
    ros_now,
    spin,
)
from evsync_ros.runtime.wire import pack
from msg_adapters.registry import Restamper, decoder_for

COUNTS_PERIOD_NS = 20_000_000
"""How often a camera process sends its messages' counts (their arrival times travel with them)."""
CHANNEL_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
"""Counts and states: reliable, deep enough for seconds of batches."""
CORRECTIONS_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""Corrections: the newest only, kept for a camera process that starts (or restarts) later."""
PARENT_ENV = 'EVSYNC_NODE_PID'
"""The environment variable that tells a camera process its evsync_node's process id."""
STOP_TIMEOUT_S = 10.0
"""How long ``evsync_node`` waits for a camera process to publish what it holds and exit."""


def counts_topic(node: str) -> str:
    return f'{node.rstrip("/")}/_counts'


def state_topic(node: str) -> str:
    return f'{node.rstrip("/")}/_camera_state'


def corrections_topic(node: str) -> str:
    return f'{node.rstrip("/")}/_corrections'


class CameraNode(MessagePath, Node):
    """One camera's message path, its correction from the estimator process (module notes)."""

    def __init__(self, index: int, estimator: str, *, clock: Callable[[], int] | None = None,
                 host_clock: Callable[[], int] | None = None, **kwargs: Any) -> None:
        """``index``: the camera's place in ``topics``; ``estimator``: the fully qualified name of the
        ``evsync_node`` it serves; the clocks as ``EvsyncNode``'s (the node's ROS clock unless given)."""
        super().__init__('evsync_camera', **kwargs)
        now = ros_now(self)
        self._arrival_clock = clock or now
        self._host_clock = host_clock or now
        self._host_stamped: dict[str, bool] = {}
        self.config = cfg = declare_parameters(self)
        if not 0 <= index < len(cfg.topics):
            raise ParameterError(f'camera process {index}: there are {len(cfg.topics)} topics')
        self.index = index
        self.topic = topic = cfg.topics[index]
        msgtype, output = cfg.types[index], cfg.outputs[index]
        qos = events_qos(cfg)
        cls = message_class(msgtype)
        st = StreamState(topic, output, decoder_for(msgtype), Restamper(msgtype, live=True))
        if cfg.republish == 'all':
            st.publisher = self.create_publisher(cls, output, output_qos(cfg))
        self.streams = {topic: st}
        st.subscription = self.create_subscription(cls, topic, functools.partial(self._on_message, st), qos,
                                                   raw=True)
        self.companions: dict[str, CompanionState] = {}
        for comp in cfg.companions:
            if comp.camera != topic or cfg.republish == 'none':
                continue
            ccls = companion_class(comp.topic, comp.msgtype)
            take, offer = companion_qos(self, comp.topic, qos, cfg.qos_depth)
            cs = CompanionState(comp.topic, comp.camera, comp.output)
            cs.publisher = self.create_publisher(ccls, comp.output, offer)
            self.companions[comp.topic] = cs
            cs.subscription = self.create_subscription(ccls, comp.topic, functools.partial(self._on_companion, cs),
                                                       take, raw=True)
        self.grid_ns = cfg.online.grid_ns
        self.pending: list[MessageBins] = []
        self.state = State.WAITING
        self.correction: ClockCorrection | None = None
        self.prior_ns: int | None = None
        self.counts_pub = self.create_publisher(Int64MultiArray, counts_topic(estimator), CHANNEL_QOS)
        self.state_pub = self.create_publisher(String, state_topic(estimator), CHANNEL_QOS)
        self.create_subscription(String, corrections_topic(estimator), self._on_corrections, CORRECTIONS_QOS)
        self.create_timer(COUNTS_PERIOD_NS / 1e9, self._send_counts)
        self.create_timer(cfg.estimate_period_ns / 1e9, lambda: self._release_held(self._arrival_clock()))
        self.create_timer(cfg.diagnostics_period_ns / 1e9, self._report)
        self.get_logger().info(f'camera process of {estimator}: {topic} -> {output}')

    # -- the message path's hooks ---------------------------------------------------------------

    def _feed(self, st: StreamState, times: TimeArray, receipt: int, raw: bytes) -> None:
        host = self._host_pair(st.topic, times, raw) if self.config.host and times.size else (None, None)
        self.pending.append(MessageBins.of(times, receipt_ns=receipt, grid_ns=self.grid_ns,
                                           host_event_ns=host[0], host_ns=host[1]))

    def _correction(self, topic: str) -> ClockCorrection | None:
        return self.correction

    def _coarse(self, st: StreamState) -> ClockCorrection | None:
        return None if self.prior_ns is None else ClockCorrection(offset_ns=self.prior_ns)

    def _passthrough(self, topic: str) -> bool:
        return topic == self.config.reference and not self.config.host

    # -- the estimator process ------------------------------------------------------------------

    def _send_counts(self) -> None:
        if not self.pending:
            return
        batch, self.pending = self.pending, []
        self.counts_pub.publish(Int64MultiArray(data=array.array('q', pack(batch, camera=self.index).tobytes())))

    def _on_corrections(self, msg: String) -> None:
        """The estimator's newest corrections: this camera's is in force from now on; held messages
        go out with it."""
        try:
            mine = json.loads(msg.data)[self.topic]
            c = mine['correction']
            self.correction = None if c is None else ClockCorrection(
                offset_ns=int(c['offset_ns']), skew_ppm=float(c['skew_ppm']), anchor_ns=int(c['anchor_ns']))
            self.prior_ns = None if mine['prior_ns'] is None else int(mine['prior_ns'])
            self.state = State(mine['state'])
        except (ValueError, KeyError, TypeError) as exc:
            self.get_logger().error(f'corrections that are not: {exc!r}', throttle_duration_sec=5.0)
            return
        self._release_held(self._arrival_clock())

    def _report(self) -> None:
        """This camera's message path, and its companions', to the estimator process (``/diagnostics``
        comes from there)."""
        values = path_values(self.streams[self.topic])
        values['topic'] = self.topic
        values['companions'] = {cs.topic: companion_values(cs) for cs in self.companions.values()}
        self.state_pub.publish(String(data=json.dumps(values)))


def start_processes(node: Node, *, ros_args: list[str]) -> dict[str, subprocess.Popen[bytes]]:
    """Start a camera process per topic of ``node`` (an ``EvsyncNode``), with its parameters (written
    to a file each reads and removes) and the ROS arguments it was started with."""
    values = {name: v for name in NODE_PARAMETERS if (v := parameter_value(node, name)) is not None}
    values = {k: list(v) if isinstance(v, (list, tuple, array.array)) else v for k, v in values.items()}
    values['use_sim_time'] = bool(parameter_value(node, 'use_sim_time'))  # on the node's clock, however it was set
    estimator = node.get_fully_qualified_name()
    processes = {}
    for index, topic in enumerate(node.config.topics):  # type: ignore[attr-defined]
        fd, name = tempfile.mkstemp(prefix=f'evsync_camera{index}_', suffix='.yaml')
        with os.fdopen(fd, 'w') as f:
            json.dump({'/**': {'ros__parameters': values}}, f)  # JSON is YAML
        command = [sys.executable, '-m', 'evsync_ros.ros.camera', str(index), estimator, name,
                   '--ros-args', '-r', f'__node:=evsync_camera{index}', '-r', f'__ns:={node.get_namespace()}',
                   '--params-file', name, *ros_args]
        env = {**os.environ, PARENT_ENV: str(os.getpid())}
        processes[topic] = subprocess.Popen(command, env=env)
    return processes


def stop_processes(processes: dict[str, subprocess.Popen[bytes]]) -> None:
    """Ask every camera process to stop (SIGTERM: it publishes what it holds first), then wait."""
    for proc in processes.values():
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + STOP_TIMEOUT_S
    for proc in processes.values():
        try:
            proc.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def main(argv: list[str] | None = None) -> int:
    """``python -m evsync_ros.ros.camera INDEX ESTIMATOR PARAMS_FILE --ros-args ...``: what
    ``evsync_node`` starts (PARAMS_FILE, written by it, is removed once read)."""
    argv = list(sys.argv if argv is None else argv)
    plain = rclpy.utilities.remove_ros_args(argv)
    if len(plain) != 4:
        print('usage: python -m evsync_ros.ros.camera INDEX ESTIMATOR PARAMS_FILE --ros-args ...', file=sys.stderr)
        return 2
    signal.signal(signal.SIGTERM, interrupt)
    try:
        parent = os.environ.get(PARENT_ENV)  # SIGTERM when evsync_node dies, however it dies
        if not die_with_parent(signal.SIGTERM, parent=None if parent is None else int(parent)):
            return 1
        return _run(argv, plain)
    finally:  # read, or never to be: however this process ends, the file evsync_node wrote for it goes
        with contextlib.suppress(OSError):
            Path(plain[3]).unlink()


def _run(argv: list[str], plain: list[str]) -> int:
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = CameraNode(int(plain[1]), plain[2])
        with contextlib.suppress(OSError):
            Path(plain[3]).unlink()
        gc.freeze()  # as evsync_node does: full collections walk only what comes after (bench/gc_pause.py)
        spin(node, executor=node.config.executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except EXPECTED_ERRORS as exc:
        print(f'evsync_node camera process {plain[1]}: {exc}', file=sys.stderr)
        return 2
    finally:
        if node is not None:
            if rclpy.utilities.ok():
                node.flush_held()
                node._send_counts()
            node.destroy_node()
        rclpy.utilities.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
