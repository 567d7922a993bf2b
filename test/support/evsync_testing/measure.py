"""What the benchmarks measure a running node with: its processes and their CPU time, and its
/diagnostics as they come."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path
from typing import Any

QOS_KINDS = ('driver', 'reliable')
"""The benchmarks' QoS choices (``qos_profile``)."""


def qos_profile(kind: str) -> Any:
    """A QoSProfile (rclpy is imported here, in the processes that publish or subscribe): ``driver``,
    what metavision_driver and libcaer_driver offer and the node's defaults (best effort, KeepLast
    1000), or ``reliable`` KeepLast 2000."""
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    if kind == 'driver':
        return QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST)
    return QoSProfile(depth=2000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)


def children(pid: int) -> list[int]:
    """The processes ``pid`` started and that still run or wait to be reaped (evsync_node's camera
    processes and its estimator process); none when ``pid`` is gone (/proc)."""
    try:
        return [int(c) for c in Path(f'/proc/{pid}/task/{pid}/children').read_text().split()]
    except OSError:
        return []


def cpu_seconds(pid: int) -> float:
    """User and system CPU seconds a process has used so far (/proc)."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


class DiagnosticsListener:
    """The node's /diagnostics while a run goes on: the states seen, and the newest report."""

    def __init__(self) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        self.rclpy = rclpy
        self.ctx = rclpy.context.Context()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node('bench_diag', context=self.ctx)
        self.states: set[str] = set()
        self.newest: dict[str, dict] = {}
        self.locked_at: dict[str, int] = {}
        """Per hardware_id (a topic), when a report first said locked (CLOCK_MONOTONIC ns, on receipt)."""
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on, 10)
        self.ex = rclpy.executors.SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.running = True
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _on(self, msg: Any) -> None:
        for s in msg.status:
            values = {kv.key: kv.value for kv in s.values}
            self.newest[s.hardware_id] = values
            self.states.add(values.get('state', '?'))
            if values.get('state') == 'locked':
                self.locked_at.setdefault(s.hardware_id, time.monotonic_ns())

    def _spin(self) -> None:
        while self.running:
            self.ex.spin_once(timeout_sec=0.1)

    def close(self) -> tuple[set[str], dict[str, dict]]:
        self.running = False
        self.thread.join(timeout=5)
        self.ex.shutdown()
        self.node.destroy_node()
        self.rclpy.shutdown(context=self.ctx)
        return self.states, self.newest
