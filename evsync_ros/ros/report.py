"""What the node publishes of its state every diagnostics period (/diagnostics, the offsets, the
numeric status topics) and logs every ``log_summary_s``: each built by a pure function
(``ros.diagnostics``, ``ros.status``, ``ros.logbook``) from the message path's counters (its own,
or its camera processes' reports), the estimate, and what the previous report saw."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import TimeReference
from std_msgs.msg import Float64

from evsync_ros.core.engine import Status
from evsync_ros.ros.diagnostics import (
    Health,
    Marks,
    companion_diagnostic,
    host_diagnostic,
    next_marks,
    stream_diagnostic,
    time_msg,
)
from evsync_ros.ros.estimator import Estimator
from evsync_ros.ros.logbook import Tally, summary
from evsync_ros.ros.modes import Republish
from evsync_ros.ros.parameters import NodeConfig
from evsync_ros.ros.path import MessagePath
from evsync_ros.ros.status import NAMES, camera_values, field_topic
from evsync_ros.ros.streams import companion_counters, path_counters
from evsync_ros.runtime.wire import CameraReport, CompanionCounters, PathCounters

__all__ = ['Reporter']


class Reporter:
    """The node's reports (module notes). ``reports``: each camera process's newest report, by
    topic (``processes: per_camera``; empty otherwise); ``process_error``: why a stream's camera
    process is gone ('' while it runs)."""

    def __init__(self, node: Node, config: NodeConfig, estimator: Estimator, path: MessagePath, *,
                 reports: Mapping[str, CameraReport], process_error: Callable[[str], str]) -> None:
        self.node = node
        self.config = config
        self.estimator = estimator
        self.path = path
        self.reports = reports
        self.process_error = process_error
        self.diagnostics_pub = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.offsets_pub = node.create_publisher(TimeReference, config.offsets_topic, 10)
        self.status_pubs: dict[str, dict[str, Any]] = {
            topic: {name: node.create_publisher(Float64, field_topic(config.status_topic, topic, name), 10)
                    for name in NAMES}
            for topic in (config.topics if config.status_topic else ())}
        """Per camera, per quantity of ``ros.status.FIELDS``: its std_msgs/Float64 publisher."""
        self.marks: dict[str, Marks] = {}
        self.tally: Tally | None = None

    def paths(self) -> dict[str, PathCounters]:
        """Each stream's message path: as its camera process last reported it, or this process's."""
        out = {}
        for topic in self.config.topics:
            report, st = self.reports.get(topic), self.path.streams.get(topic)
            out[topic] = report.path if report else path_counters(st) if st else PathCounters()
        return out

    def companions(self) -> dict[str, CompanionCounters]:
        """Each companion's message path, as ``paths`` (none with ``republish: none``)."""
        out: dict[str, CompanionCounters] = {}
        if self.config.republish is Republish.NONE:
            return out
        for comp in self.config.companions:
            report, cs = self.reports.get(comp.camera), self.path.companions.get(comp.topic)
            if report and comp.topic in report.companions:
                out[comp.topic] = report.companions[comp.topic]
            else:
                out[comp.topic] = companion_counters(cs) if cs else CompanionCounters()
        return out

    def report(self) -> None:
        """/diagnostics, the offsets and the status topics, now."""
        est, sync = self.estimator, self.estimator.sync
        now = est.clock()
        started = est.started(now)
        health = Health(now_ns=now, started_ns=started, silent_start=now - started > self.config.online.window_ns,
                        worker_error=est.worker_error, estimator_restarts=est.restarts)
        array = DiagnosticArray()
        array.header.stamp = self.node.get_clock().now().to_msg()
        companions = self.companions()
        for comp in self.config.companions:
            if comp.topic in companions:
                array.status.append(companion_diagnostic(comp.topic, comp.camera, comp.output,
                                                         companions[comp.topic], sync.state(comp.camera)))
        for topic, path in self.paths().items():
            status = sync.status(topic, now_ns=now)
            marks = self.marks.get(topic, Marks())
            array.status.append(stream_diagnostic(topic, path, status, marks, health,
                                                  envelope_latency_ns=sync.latency_delta_ns[topic],
                                                  process_error=self.process_error(topic)))
            self.marks[topic] = next_marks(path, status, health)
            self._publish_offsets(topic, status, path)
        if est.host is not None:
            array.status.append(host_diagnostic(est.host_fit, est.host_error))
        self.diagnostics_pub.publish(array)

    def _publish_offsets(self, topic: str, status: Status, path: PathCounters) -> None:
        """A camera's numeric status, and its TimeReference as sensor_msgs/TimeReference defines it:
        header.stamp the time on the rig's timeline (the reference camera's, or the host's), time_ref
        the same instant on the camera's own clock."""
        host = self.estimator.host is not None
        c = status.correction if not host else self.estimator.correction(topic)
        pubs = self.status_pubs.get(topic)
        if pubs:
            for name, value in camera_values(status, correction=c, last_time_ns=path.last_time_ns,
                                             lost=path.messages_lost).items():
                pubs[name].publish(Float64(data=value))
        if (topic != self.config.reference or host) and c is not None and path.last_time_ns is not None:
            ref = TimeReference()
            ref.header.stamp = time_msg(c.apply_one(path.last_time_ns))
            ref.time_ref = time_msg(path.last_time_ns)
            ref.source = topic
            self.offsets_pub.publish(ref)

    def log_summary(self) -> None:
        """The log's line for every camera."""
        now = self.estimator.clock()
        statuses = [self.estimator.sync.status(t, now_ns=now) for t in self.config.topics]
        line, self.tally = summary(statuses, self.paths(), self.tally, now, reference=self.config.reference)
        self.node.get_logger().info(line)
