"""``processes: per_camera``, the node's side: a camera process per topic (``ros.camera``) started
and stopped with the node; their counts into the estimate, their reports of their message paths
into /diagnostics, the estimator's corrections out to them.

Each camera process sends its messages as counts on the estimator's grid (``core.counts``) every
``COUNTS_PERIOD_NS`` on ``<node>/_counts``, and its message path's counters (and its companions')
every diagnostics period on ``<node>/_camera_state``; it restamps with what the estimator
publishes on ``<node>/_corrections`` (latched). These three topics are hidden (their names begin
with ``_``) and internal: their form (``runtime.wire``) may change between versions."""

from __future__ import annotations

import array
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Int64MultiArray, String

from evsync_ros.core.errors import StreamError
from evsync_ros.ros.declare import parameter_value, qos_overrides
from evsync_ros.ros.estimator import Estimator
from evsync_ros.ros.parameters import NODE_PARAMETERS, NodeConfig
from evsync_ros.runtime.wire import (
    CameraCorrection,
    CameraReport,
    decode_report,
    encode_corrections,
    unpack,
)

__all__ = ['CameraLink', 'corrections_topic', 'counts_topic', 'state_topic']

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


class CameraLink:
    """The node's camera processes and what goes between them and its estimate (module notes)."""

    def __init__(self, node: Node, config: NodeConfig, estimator: Estimator) -> None:
        base = node.get_fully_qualified_name()
        self.node, self.config, self.estimator = node, config, estimator
        self.counts_source = counts_topic(base)
        self.reports: dict[str, CameraReport] = {}
        """Each stream's message path as its camera process last reported it."""
        self.processes: dict[str, subprocess.Popen[bytes]] = {}
        self.bad_batches = 0
        node.create_subscription(Int64MultiArray, self.counts_source, self._on_counts, CHANNEL_QOS)
        node.create_subscription(String, state_topic(base), self._on_report, CHANNEL_QOS)
        self.corrections_pub = node.create_publisher(String, corrections_topic(base), CORRECTIONS_QOS)
        estimator.after = self.publish_corrections

    def _on_counts(self, msg: Int64MultiArray) -> None:
        """A camera process's batch of messages, counted on the grid: into the estimate."""
        try:
            index, messages = unpack(np.frombuffer(msg.data, np.int64), source=self.counts_source)
            topic = self.config.topics[index]
        except (StreamError, IndexError) as exc:
            self.bad_batches += 1
            self.node.get_logger().error(f'{exc} ({self.bad_batches} batches left out so far)',
                                         throttle_duration_sec=5.0)
            return
        self.estimator.add_counts(topic, messages)

    def _on_report(self, msg: String) -> None:
        try:
            report = decode_report(msg.data, source='a camera process')
        except StreamError as exc:
            self.node.get_logger().error(str(exc), throttle_duration_sec=5.0)
            return
        self.reports[report.topic] = report

    def publish_corrections(self) -> None:
        """What each camera process's messages get now."""
        est = self.estimator
        self.corrections_pub.publish(String(data=encode_corrections({
            topic: CameraCorrection(est.sync.state(topic), est.prior(topic), est.correction(topic))
            for topic in self.config.topics})))

    def process_error(self, topic: str) -> str:
        """Why a stream's camera process is gone ('' while it runs, or before it started)."""
        proc = self.processes.get(topic)
        if proc is None or proc.poll() is None:
            return ''
        return f'its camera process exited with status {proc.returncode}; its messages are not republished'

    def start(self, *, ros_args: list[str]) -> None:
        """A camera process per topic, with the node's parameters (written to a file each reads and
        removes: the node's own, however they were set, and its QoS overrides) and the ROS arguments
        it was started with."""
        node = self.node
        values: dict[str, Any] = {name: v for name in NODE_PARAMETERS if (v := parameter_value(node, name)) is not None}
        values = {k: list(v) if isinstance(v, (list, tuple, array.array)) else v for k, v in values.items()}
        values['use_sim_time'] = bool(parameter_value(node, 'use_sim_time'))  # on the node's clock, however set
        for name, value in qos_overrides(node).items():  # nested, as a parameter file writes them
            where = values
            *parents, last = name.split('.')
            for key in parents:
                where = where.setdefault(key, {})
            where[last] = value
        for index, topic in enumerate(self.config.topics):
            fd, name = tempfile.mkstemp(prefix=f'evsync_camera{index}_', suffix='.yaml')
            with os.fdopen(fd, 'w') as f:
                json.dump({'/**': {'ros__parameters': values}}, f)  # JSON is YAML
            command = [sys.executable, '-m', 'evsync_ros.ros.camera', str(index), node.get_fully_qualified_name(),
                       name, '--ros-args', '-r', f'__node:=evsync_camera{index}', '-r',
                       f'__ns:={node.get_namespace()}', '--params-file', name, *ros_args]
            self.processes[topic] = subprocess.Popen(command, env={**os.environ, PARENT_ENV: str(os.getpid())})

    def stop(self) -> None:
        """Ask every camera process to stop (SIGTERM: it publishes what it holds first), then wait."""
        for proc in self.processes.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + STOP_TIMEOUT_S
        for proc in self.processes.values():
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
