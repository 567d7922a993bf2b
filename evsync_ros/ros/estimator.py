"""The node's estimate: the engine its message path feeds (``Sink``), the host line with
``reference: host``, the corrections its messages get (``Corrections``), and the thread that steps
them when the estimation timer wakes it. Each camera's state changes go to the log as they happen
(``ros.logbook``)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.counts import MessageBins
from evsync_ros.core.density import TimeArray
from evsync_ros.core.engine import Engine, State, feed
from evsync_ros.core.errors import StreamError
from evsync_ros.core.host import HostFit, HostTracker
from evsync_ros.core.runner import Runner
from evsync_ros.ros.clock import HostStamps
from evsync_ros.ros.diagnostics import estimator_restarted
from evsync_ros.ros.logbook import Level, Seen, changes
from evsync_ros.ros.parameters import NodeConfig
from evsync_ros.ros.streams import StreamState
from msg_adapters.edges import TriggerEdges
from msg_adapters.events import Stepped

__all__ = ['Estimator']


class Estimator:
    """The engine, the host line and the estimation thread of one node (module notes)."""

    def __init__(self, config: NodeConfig, *, clock: Callable[[], int], stamps: HostStamps, logger: Any) -> None:
        """``clock``: when messages arrive (ns); ``stamps``: when the host had them, what ``reference:
        host`` puts the rig on; ``logger``: the node's."""
        self.config = config
        self.clock = clock
        self.logger = logger
        self.sync = Engine(config.topics, reference=config.reference, params=config.online,
                               latencies_ns=config.latencies_ns)
        self.host = HostTracker(span_ns=config.online.drift_span_ns, floor_ns=config.host_floor_ns) \
            if config.host else None
        """reference host: the cameras' common timeline onto host time (None: a camera is the reference)."""
        self.stamps = stamps
        self.host_fit: HostFit | None = None
        self.host_error = ''
        self.worker_error: BaseException | None = None
        """What stopped the estimation thread (None: it runs)."""
        self.restarts = 0
        """Times the estimator process died and was started again (warned of in the log and /diagnostics)."""
        self._started_ns: int | None = None
        self.after: Callable[[], None] = lambda: None
        """Called after each estimate (per_camera: the corrections sent)."""
        self.seen: dict[str, Seen] = {}
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._work, name='evsync-estimator', daemon=True)
        self._thread.start()
        self.started(clock())

    def started(self, now: int) -> int:
        """When the node's clock first ran: its first non-zero reading (``use_sim_time`` reads 0 until
        the first /clock), ``now`` taken as one."""
        if self._started_ns is None and now:
            self._started_ns = now
        return now if self._started_ns is None else self._started_ns

    # -- the message path's sink (message threads) ------------------------------------------------

    def feed(self, st: StreamState, times: TimeArray, receipt: int, raw: bytes) -> None:
        self.started(receipt)
        if self.host is not None and times.size and (pair := self.stamps.pair(st.topic, times, raw)):
            self.host.add(st.topic, *pair)
        self.sync.add(st.topic, times, receipt)

    def counted(self, st: StreamState, step: Stepped, receipt: int, raw: bytes) -> None:
        if self.host is not None or step.counts is None:  # the host line pairs times with stamps
            self.feed(st, step.times, receipt, raw)
            return
        self.started(receipt)
        feed.add_counted(self.sync, st.topic, step.times, receipt, lo=step.lo, hi=step.hi, mid=step.mid, k0=step.k0,
                         counts=step.counts)

    def edges(self, st: StreamState, edges: TriggerEdges) -> None:
        feed.add_edges(self.sync, st.topic, edges.t, edges.value)

    def modelled(self, st: StreamState) -> None:
        self.sync.set_model(st.topic, st.model)  # another model than the reference's: more error, as offline

    def add_counts(self, topic: str, messages: list[MessageBins]) -> None:
        """per_camera: a camera process's batch of messages, counted on the grid."""
        for m in messages:
            if self.host is not None and m.host_event_ns is not None and m.host_ns is not None:
                self.host.add(topic, m.host_event_ns, m.host_ns)
            self.sync.add_bins(topic, m)

    # -- the corrections messages get -------------------------------------------------------------

    def correction(self, topic: str) -> ClockCorrection | None:
        """Onto the reference camera's timeline, and with reference host onto the host clock (None:
        not locked, or the host line not fitted yet)."""
        c = self.sync.correction(topic)
        if self.host is None or c is None:
            return c
        fit = self.host_fit
        return None if fit is None else c.then(fit.correction)

    def prior(self, topic: str) -> int | None:
        """The offset seen in arrival times (onto the host clock with ``reference: host``)."""
        return self.sync.prior(topic) if self.host is None else self.host.prior(topic)

    def coarse(self, topic: str) -> ClockCorrection | None:
        prior = self.prior(topic)
        return None if prior is None else ClockCorrection(offset_ns=prior)

    def passthrough(self, topic: str) -> bool:
        return topic == self.config.reference and self.host is None

    # -- estimating (its thread) ------------------------------------------------------------------

    @property
    def runner(self) -> Runner:
        """Where the windows are fitted and their agreement found (``Engine.runner``)."""
        return self.sync.runner

    def start(self, runner: Runner) -> None:
        """Fit in ``runner`` from now on (until then the sync fits in its own thread)."""
        self.sync.runner = runner

    def wake(self) -> None:
        """The estimation timer: one estimate, in the estimation thread."""
        self._wake.set()

    def _work(self) -> None:
        try:
            while not self._stop.is_set():
                self._wake.wait()
                self._wake.clear()
                if self._stop.is_set():
                    return
                self.estimate(self.clock())
        except BaseException as exc:  # noqa: BLE001 (reported in /diagnostics and the log, not lost)
            self.worker_error = exc
            self.logger.error(f'estimation stopped: {exc!r}')

    def estimate(self, now_ns: int) -> None:
        """One estimate at ``now_ns`` (arrival clock): every camera stepped (``Engine.step``), the
        host line, what changed logged, and ``after``. The estimation thread calls it on each wake; a
        replay in recorded time calls it instead."""
        self.sync.step(now_ns)
        if self.runner.restarts > self.restarts:  # the estimator process died, and was replaced
            self.restarts = self.runner.restarts
            self.logger.warning(f'{estimator_restarted(self.restarts)}; now {self.runner.where}')
        self._fit_host()
        self._log_changes(now_ns)
        self.after()

    def _fit_host(self) -> None:
        """reference host: the host line through every locked camera's least arrival lags."""
        if self.host is None:
            return
        locked = {t: c for t in self.config.topics
                  if self.sync.state(t) is State.LOCKED and (c := self.sync.correction(t)) is not None}
        fitted = self.host_fit is not None
        try:
            self.host_fit = self.host.fit(locked)
            self.host_error = ''
        except StreamError as exc:
            self.host_error = str(exc)
        if not fitted and self.host_fit is not None:
            fit = self.host_fit
            self.logger.info(f'on host time: the rig {fit.offset_ns / 1e6:+.3f} ms from host time at its anchor, '
                             f'+- {fit.uncertainty_ns / 1e6:.3f} ms (floor aside), skew {fit.skew_ppm:+.2f} ppm')

    def _log_changes(self, now_ns: int) -> None:
        for topic in self.config.topics:
            lines, self.seen[topic] = changes(self.sync.status(topic, now_ns=now_ns), self.seen.get(topic),
                                              reference=topic == self.config.reference)
            for level, text in lines:  # one call line per severity: rclpy's logger holds a line to one
                if level is Level.WARN:
                    self.logger.warning(text)
                else:
                    self.logger.info(text)

    def stop(self) -> None:
        """Stop the estimation thread (on shutdown; a replay that steps the estimator itself, in
        recorded time, stops it so that nothing else steps it at the same time)."""
        self._stop.set()
        self._wake.set()
        self._thread.join(timeout=5.0)

    def close(self) -> None:
        self.stop()
        self.runner.close()
