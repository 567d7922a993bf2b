"""A node of a context of its own, spun by a thread of this process: what the tests and the path
runner listen to the node's outputs with over real DDS (rclpy imported when one is made)."""

from __future__ import annotations

import threading
from typing import Any

__all__ = ['Spinning', 'diagnostics_of']


class Spinning:
    """``rclpy`` initialised in a context of its own (``domain_id``: a DDS domain of its own, else
    the environment's), one node in it; ``start`` spins it in a thread, ``close`` ends both."""

    def __init__(self, name: str, *, domain_id: int | None = None) -> None:
        import rclpy
        self.context = rclpy.context.Context()
        if domain_id is None:
            rclpy.init(context=self.context)
        else:
            rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._run = False
        self.thread = threading.Thread(target=self._spin, daemon=True)

    def start(self) -> None:
        """Spin the node from now on (its subscriptions made)."""
        self._run = True
        self.thread.start()

    def _spin(self) -> None:
        while self._run:
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        import rclpy
        self._run = False
        if self.thread.is_alive():
            self.thread.join(timeout=5)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def diagnostics_of(msg: Any) -> dict[str, dict[str, Any]]:
    """A DiagnosticArray as {hardware_id: {'level': int, 'message': str, key: value, ...}}."""
    per = {}
    for s in msg.status:
        level = int.from_bytes(s.level, 'little') if isinstance(s.level, bytes) else int(s.level)
        per[s.hardware_id] = {'level': level, 'message': s.message, **{kv.key: kv.value for kv in s.values}}
    return per
