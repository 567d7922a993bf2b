"""A camera process of ``evsync_node`` with ``processes: per_camera``: one camera's message path (its
events and companions decoded, restamped, republished) in a process of its own, so that the message
work of several cameras at 1 kHz spreads over cores (and, DDS carrying the topics, over hosts).
``evsync_node`` starts one per topic and stops them as it stops (``ros.cameras``, which also says
what goes between them)."""

from __future__ import annotations

import array
import contextlib
import gc
import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import rclpy
import rclpy.utilities
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Int64MultiArray, String

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.counts import MessageBins
from evsync_ros.core.density import TimeArray
from evsync_ros.core.errors import StreamError
from evsync_ros.errors import EXPECTED_ERRORS, ParameterError
from evsync_ros.lifetime import die_with_parent
from evsync_ros.ros.cameras import (
    CHANNEL_QOS,
    CORRECTIONS_QOS,
    COUNTS_PERIOD_NS,
    PARENT_ENV,
    corrections_topic,
    counts_topic,
    state_topic,
)
from evsync_ros.ros.clock import ArrivalClock, HostStamps
from evsync_ros.ros.declare import declare_parameters
from evsync_ros.ros.parameters import NodeConfig
from evsync_ros.ros.path import MessagePath
from evsync_ros.ros.spin import interrupt, spin
from evsync_ros.ros.streams import StreamState, companion_counters, path_counters
from evsync_ros.ros.topics import open_companions, open_stream
from evsync_ros.runtime.wire import CameraCorrection, CameraReport, decode_corrections, encode_report, pack
from msg_adapters.edges import TriggerEdges
from msg_adapters.events import Stepped

__all__ = ['CameraNode', 'main']


class FromEstimator:
    """A camera process's corrections: what the estimator process last published for its camera."""

    def __init__(self, topic: str, config: NodeConfig) -> None:
        self.topic = topic
        self.reference = config.reference
        self.host = config.host
        self.now: CameraCorrection | None = None

    def correction(self, topic: str) -> ClockCorrection | None:
        return None if self.now is None else self.now.correction

    def coarse(self, topic: str) -> ClockCorrection | None:
        prior = None if self.now is None else self.now.prior_ns
        return None if prior is None else ClockCorrection(offset_ns=prior)

    def passthrough(self, topic: str) -> bool:
        return topic == self.reference and not self.host


class Batches:
    """A camera process's sink: each message counted on the estimator's grid, with when it arrived
    (and, with ``reference: host``, when the host had it), until the next batch goes."""

    def __init__(self, grid_ns: int, stamps: HostStamps | None) -> None:
        self.grid_ns = grid_ns
        self.stamps = stamps
        self.pending: list[MessageBins] = []

    def feed(self, st: StreamState, times: TimeArray, receipt: int, raw: bytes) -> None:
        pair = self.stamps.pair(st.topic, times, raw) if self.stamps and times.size else None
        event, host = pair or (None, None)
        self.pending.append(MessageBins.of(times, receipt_ns=receipt, grid_ns=self.grid_ns, host_event_ns=event,
                                           host_ns=host))

    def counted(self, st: StreamState, step: Stepped, receipt: int, raw: bytes) -> None:
        if step.counts is None or self.stamps:  # (``reference: host`` pairs times with stamps)
            self.feed(st, step.times, receipt, raw)
            return
        self.pending.append(MessageBins.of_dense(step.counts, step.k0, receipt_ns=receipt, mid_ns=step.mid,
                                                 lo_ns=step.lo, hi_ns=step.hi))

    def modelled(self, st: StreamState) -> None:
        """The estimator knows a camera's model from its node's own decode only."""

    def edges(self, st: StreamState, edges: TriggerEdges) -> None:
        """Trigger edges are read in the node's process only (``trigger_channels`` asks ``processes: one``)."""

    def take(self) -> list[MessageBins]:
        batch, self.pending = self.pending, []
        return batch


class CameraNode(Node):
    """One camera's message path, its correction from the estimator process (module notes)."""

    def __init__(self, index: int, estimator: str, *, clock: Callable[[], int] | None = None,
                 host_clock: Callable[[], int] | None = None, **kwargs: Any) -> None:
        """``index``: the camera's place in ``topics``; ``estimator``: the fully qualified name of the
        ``evsync_node`` it serves; the clocks as ``EvsyncNode``'s (the node's ROS clock unless given)."""
        super().__init__('evsync_camera', **kwargs)
        arrival = ArrivalClock(self)
        self.config = cfg = declare_parameters(self)
        if not 0 <= index < len(cfg.topics):
            raise ParameterError(f'camera process {index}: there are {len(cfg.topics)} topics')
        self.index, self.topic = index, cfg.topics[index]
        self.corrections = FromEstimator(self.topic, cfg)
        stamps = HostStamps(host_clock) if host_clock else HostStamps(arrival, sure=arrival.sure)
        self.batches = Batches(cfg.online.grid_ns, stamps if cfg.host else None)
        self.path = MessagePath(corrections=self.corrections, sink=self.batches, clock=clock or arrival,
                                before_lock=cfg.before_lock, hold_limit_ns=cfg.hold_limit_ns, qos_depth=cfg.qos_depth,
                                grid_ns=cfg.online.grid_ns,
                                warn=self.get_logger().warning)
        open_stream(self, self.path, cfg, index)
        open_companions(self, self.path, cfg, [self.topic])
        self.counts_pub = self.create_publisher(Int64MultiArray, counts_topic(estimator), CHANNEL_QOS)
        self.state_pub = self.create_publisher(String, state_topic(estimator), CHANNEL_QOS)
        self.create_subscription(String, corrections_topic(estimator), self._on_corrections, CORRECTIONS_QOS)
        self.create_timer(COUNTS_PERIOD_NS / 1e9, self.send_counts)
        self.create_timer(cfg.estimate_period_ns / 1e9, lambda: self.path.release_held(self.path.clock()))
        self.create_timer(cfg.diagnostics_period_ns / 1e9, self._report)
        self.get_logger().info(f'camera process of {estimator}: {self.topic} -> {cfg.outputs[index]}')

    def send_counts(self) -> None:
        batch = self.batches.take()
        if batch:
            self.counts_pub.publish(Int64MultiArray(data=array.array('q', pack(batch, camera=self.index).tobytes())))

    def _on_corrections(self, msg: String) -> None:
        """The estimator's newest corrections: this camera's is in force from now on; held messages
        go out with it."""
        try:
            self.corrections.now = decode_corrections(msg.data, source='the estimator')[self.topic]
        except (StreamError, KeyError) as exc:
            self.get_logger().error(f'corrections that are not: {exc!r}', throttle_duration_sec=5.0)
            return
        self.path.release_held(self.path.clock())

    def _report(self) -> None:
        """This camera's message path, and its companions', to the estimator process (``/diagnostics``
        comes from there)."""
        report = CameraReport(self.topic, path_counters(self.path.streams[self.topic]),
                              {t: companion_counters(cs) for t, cs in self.path.companions.items()})
        self.state_pub.publish(String(data=encode_report(report)))


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
                node.path.flush_held()
                node.send_counts()
            node.destroy_node()
        rclpy.utilities.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
