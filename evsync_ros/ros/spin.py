"""How the node's processes spin and stop: an executor chosen by ``executor``, driven until SIGINT
or SIGTERM, which leave what is held to be published on the way out."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType

import rclpy.executors
from rclpy.context import Context
from rclpy.executors import Executor as RclpyExecutor
from rclpy.node import Node

from evsync_ros.ros.modes import Executor

__all__ = ['STOP', 'interrupt', 'interrupt_ignored', 'spin']

STOP = threading.Event()
"""Set by SIGINT or SIGTERM (``interrupt``): the spin returns, and the node shuts down as its ``main`` says."""


def _events_executor(context: Context) -> RclpyExecutor | None:
    """rclpy's EventsExecutor, whose C++ dispatch costs a third of ``rclpy.spin``'s per message
    (bench/node.py, relay rows), or None where this rclpy has none."""
    try:
        from rclpy.experimental.events_executor import EventsExecutor
    except ImportError:
        return None
    return EventsExecutor(context=context)


EXECUTORS: dict[Executor, Callable[[Context], RclpyExecutor | None]] = {
    Executor.EVENTS: _events_executor,
    Executor.SINGLE_THREADED: lambda context: rclpy.executors.SingleThreadedExecutor(context=context),
}
"""Each ``executor``'s, for a node's context (None: not in this rclpy)."""
SAID = {Executor.EVENTS: "executor: rclpy's EventsExecutor", Executor.SINGLE_THREADED: 'executor: rclpy.spin'}


def spin(node: Node, *, executor: Executor) -> None:
    """Take ``node``'s callbacks until its context shuts down or SIGINT or SIGTERM (``interrupt``)
    stops it. Either executor is driven by ``spin_once``, which lets the GIL go while it waits (the
    EventsExecutor's ``spin()``, rclpy 7.1.5, never returned here and kept signals from being
    handled), and which leaves a signal to be seen between callbacks, never inside one."""
    chosen = EXECUTORS[executor](node.context)
    if chosen is None:
        node.get_logger().warning(f'executor {executor}: this rclpy has none; spinning with rclpy.spin')
        executor = Executor.SINGLE_THREADED
        chosen = EXECUTORS[executor](node.context)
        assert chosen is not None
    node.get_logger().info(SAID[executor])
    chosen.add_node(node)
    try:
        while node.context.ok() and not STOP.is_set():
            chosen.spin_once(timeout_sec=0.1)
    finally:
        chosen.shutdown()


def interrupt(signum: int, frame: FrameType | None) -> None:
    """SIGINT and SIGTERM: the spin stops after the callback under way, and what is held can still go
    out (``STOP``); a second one, while the node shuts down, stops it there (KeyboardInterrupt)."""
    if STOP.is_set():
        raise KeyboardInterrupt
    STOP.set()


@contextlib.contextmanager
def interrupt_ignored() -> Iterator[None]:
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
