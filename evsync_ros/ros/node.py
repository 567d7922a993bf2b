"""evsync_node: synchronise event cameras online and republish every stream on the reference's timeline.
What it subscribes to and publishes, and its parameters: docs/node.md (``evsync_node --help``)."""

from __future__ import annotations

import dataclasses
import gc
import signal
import sys
from collections.abc import Callable
from typing import Any

import rclpy
import rclpy.utilities
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from evsync_ros.core.engine import Method
from evsync_ros.errors import EXPECTED_ERRORS, ParameterError
from evsync_ros.ros.cameras import CameraLink
from evsync_ros.ros.clock import ArrivalClock, HostStamps
from evsync_ros.ros.declare import declare_parameters, warn_unknown
from evsync_ros.ros.estimator import Estimator
from evsync_ros.ros.messages import companion_class
from evsync_ros.ros.modes import BeforeLock, Processes, Republish
from evsync_ros.ros.operations import Services
from evsync_ros.ros.parameters import checked_value
from evsync_ros.ros.path import MessagePath
from evsync_ros.ros.qos import output_qos
from evsync_ros.ros.report import Reporter
from evsync_ros.ros.spin import interrupt, interrupt_ignored, spin
from evsync_ros.ros.topics import open_companions, open_stream
from evsync_ros.ros.usage import usage, wants_help
from evsync_ros.runtime.runner import runner

__all__ = ['EvsyncNode', 'main']

BEST_EFFORT_SAID = ('outputs offered best effort (output_reliability: best_effort, the default: reliable outputs lost '
                    'messages at 4 cameras on our benchmark host, docs/node.md); a subscriber that asks reliable, as '
                    "message_filters' does by default, receives nothing: set output_reliability: reliable for it")
"""What the node says at start of its outputs' reliability, when it is best effort."""
CLOCK_WAIT_S = 5.0
"""With ``use_sim_time``: how long the node waits for a first /clock before it warns."""


class EvsyncNode(Node):
    """The live node: its parameters, topics, timers and services wired around the message path
    it owns (``path``), its estimate (``estimator``) and its reports (``reporter``)."""

    def __init__(self, *, clock: Callable[[], int] | None = None, host_clock: Callable[[], int] | None = None,
                 **kwargs: Any) -> None:
        """``clock``: when messages arrive, in ns; ``host_clock``: the host's time, what ``reference:
        host`` puts the rig on. Both are the node's ROS clock (``ros.clock``) unless given (tests
        replay recorded arrival times)."""
        super().__init__('evsync', **kwargs)
        self.config = cfg = declare_parameters(self)
        warn_unknown(self, cfg)
        arrival = ArrivalClock(self)
        stamps = HostStamps(host_clock) if host_clock else HostStamps(arrival, sure=arrival.sure)
        self.estimator = est = Estimator(cfg, clock=clock or arrival, stamps=stamps, logger=self.get_logger())
        self.path = MessagePath(corrections=est, sink=est, clock=clock or arrival, before_lock=cfg.before_lock,
                                hold_limit_ns=cfg.hold_limit_ns, qos_depth=cfg.qos_depth,
                                grid_ns=cfg.online.grid_ns,
                                warn=self.get_logger().warning)
        self.cameras = CameraLink(self, cfg, est) if cfg.processes is Processes.PER_CAMERA else None
        if self.cameras is None:
            for index in range(len(cfg.topics)):
                open_stream(self, self.path, cfg, index)
            open_companions(self, self.path, cfg, cfg.topics)
        else:  # their camera processes take them; a type without a Header stops the node here
            for comp in cfg.companions:
                companion_class(comp.topic, comp.msgtype)
        self.reporter = Reporter(self, cfg, est, self.path, reports=self.cameras.reports if self.cameras else {},
                                 process_error=self.cameras.process_error if self.cameras else lambda topic: '')
        self.create_timer(cfg.estimate_period_ns / 1e9, self.on_estimate_timer)
        self.report_timer = self.create_timer(cfg.diagnostics_period_ns / 1e9, self.reporter.report)
        if cfg.log_summary_ns:
            self.create_timer(cfg.log_summary_ns / 1e9, self.reporter.log_summary)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        if self.get_parameter('use_sim_time').value:  # its timers wait for /clock: say so if none comes
            self._clock_check = self.create_timer(CLOCK_WAIT_S, self._on_clock_check,
                                                  clock=Clock(clock_type=ClockType.STEADY_TIME))
        Services(self, est.sync, cfg.offsets_file).seed()  # ParameterError: exit 2, naming the file
        # the estimator's process starts last, once nothing else here can fail and leave it behind
        with interrupt_ignored():  # Ctrl-C reaches the whole process group: the node stops the estimator
            est.start(runner(cfg.estimator, nice=cfg.estimator_nice))
        offered = output_qos(cfg).reliability
        reliability = offered.name.lower()
        if offered == ReliabilityPolicy.BEST_EFFORT and cfg.republish is Republish.ALL:
            self.get_logger().info(BEST_EFFORT_SAID)
        self.get_logger().info(
            f'synchronising {len(cfg.topics)} streams onto {"host time" if cfg.host else cfg.reference} '
            f'({Method(cfg.online.method).value}); outputs {", ".join(cfg.outputs)} ({reliability}, depth '
            f'{cfg.qos_depth}); before the lock: {cfg.before_lock}; {est.runner.where}')

    def on_estimate_timer(self) -> None:
        """An estimate in the estimation thread; what was held and may go, out."""
        self.estimator.wake()
        self.path.release_held(self.path.clock())

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """``ros2 param set`` of a RUNTIME parameter (rclpy refuses the read-only ones): checked as at
        start, then in force from the next message, estimate or report."""
        try:
            values = {p.name: checked_value(p.name, p.value, source=f'node {self.get_fully_qualified_name()}')
                      for p in params}
            if 'before_lock' in values and self.cameras is not None:
                raise ParameterError('before_lock is set at start with processes per_camera (each camera '
                                     'process reads it once)')
            if 'min_confidence' in values:
                self.estimator.sync.retune(min_confidence=values['min_confidence'])
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if 'diagnostics_period_s' in values:
            period = round(values['diagnostics_period_s'] * 1e9)
            self.report_timer.timer_period_ns = period
            self.config = dataclasses.replace(self.config, diagnostics_period_ns=period)
        if 'before_lock' in values:
            self.path.before_lock = BeforeLock(values['before_lock'])
            self.config = dataclasses.replace(self.config, before_lock=self.path.before_lock)
        self.get_logger().info(f'parameters set: {values}')
        return SetParametersResult(successful=True)

    def _on_clock_check(self) -> None:
        self._clock_check.cancel()
        if not self.get_clock().now().nanoseconds:
            self.get_logger().warning(f'use_sim_time is set and no /clock came in {CLOCK_WAIT_S:g} s: messages are '
                                      'republished, but nothing is estimated or reported until one comes (a bag '
                                      'player publishes it with --clock)')

    def shut_down(self) -> None:
        """Its camera processes stopped, what it holds published (while rclpy runs), its estimator
        stopped, the node destroyed."""
        if self.cameras is not None:
            self.cameras.stop()
        flushed = self.path.flush_held() if rclpy.utilities.ok() else 0
        if flushed:
            self.get_logger().info(f'shutting down: {flushed} held messages published')
        self.destroy_node()

    def destroy_node(self) -> None:
        self.estimator.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """The ``evsync_node`` entry point: spin the node until SIGINT or SIGTERM, publish what it holds,
    shut down; exit status 2 (the parameter named) when its parameters do not check out. With
    ``processes: per_camera`` it starts a camera process per topic and stops them as it stops."""
    argv = list(sys.argv if args is None else args)
    if wants_help(argv):
        print(usage(), end='')
        return 0
    sys.setswitchinterval(0.0005)  # the estimator thread yields the GIL to the message path often
    # SIGINT and SIGTERM stop the spin here, not rclpy's context, so held messages can still go out
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    signal.signal(signal.SIGINT, interrupt)
    signal.signal(signal.SIGTERM, interrupt)
    node = None
    try:
        node = EvsyncNode()
        if node.cameras is not None:
            with interrupt_ignored():  # they stop when the node tells them, not on Ctrl-C
                node.cameras.start(ros_args=argv[argv.index('--ros-args') + 1:] if '--ros-args' in argv else [])
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
            node.shut_down()
        rclpy.utilities.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
