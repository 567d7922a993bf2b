"""What /diagnostics says of each stream, companion and the host line: pure functions of what the
message path counted (``runtime.wire``'s records, local or a camera process's), the estimate's
``Status``, and what the previous report saw (``Marks``)."""

from __future__ import annotations

from dataclasses import dataclass

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from evsync_ros.core.engine import State, Status
from evsync_ros.core.host import HostFit
from evsync_ros.runtime.wire import CompanionCounters, PathCounters

__all__ = ['Marks', 'companion_diagnostic', 'estimator_restarted', 'host_diagnostic', 'next_marks',
           'stream_diagnostic', 'time_msg']


@dataclass(frozen=True)
class Marks:
    """What a stream's previous report saw: a WARN while a count grows, an event rate since."""

    lost: int = 0
    """Messages lost upstream (seq gaps)."""
    seeds: int = 0
    """Saved offsets replaced."""
    restarts: int = 0
    """Estimator processes started again."""
    rate: tuple[int, int] | None = None
    """(arrival time, events)."""


@dataclass(frozen=True)
class Health:
    """What the node knows of itself at a report."""

    now_ns: int
    started_ns: int
    """When its clock first ran."""
    silent_start: bool
    """Long enough since it started that a stream with no events is an error."""
    worker_error: BaseException | None = None
    """Why the estimation stopped (None: it runs)."""
    estimator_restarts: int = 0


def next_marks(path: PathCounters, s: Status, health: Health) -> Marks:
    """What the next report of the stream compares with."""
    return Marks(lost=path.messages_lost, seeds=s.seeds_replaced, restarts=health.estimator_restarts,
                 rate=(health.now_ns, s.events))


def estimator_restarted(restarts: int) -> str:
    """What the log and /diagnostics say when an estimator process died and a new one took over."""
    return f'the estimator process died and was started again ({restarts} so far)'


def stream_diagnostic(topic: str, path: PathCounters, s: Status, marks: Marks, health: Health, *,
                      envelope_latency_ns: int, process_error: str = '') -> DiagnosticStatus:
    """One stream's status: OK locked, WARN estimating, lost or bad messages, an estimator process
    started again since the last report, ERROR no events since the start (``health.silent_start``),
    the estimator stopped or the stream's camera process did (``process_error``); every counter as
    a value."""
    level, message = _level(path, s, marks, health)
    if process_error:
        level, message = DiagnosticStatus.ERROR, process_error
    c = s.correction
    rate = ''
    if marks.rate is not None and health.now_ns > marks.rate[0]:
        rate = f'{max(0, s.events - marks.rate[1]) * 1e9 / (health.now_ns - marks.rate[0]):.0f}'
    values = {
        'state': s.state.value, 'offset_ns': c.offset_ns if c else '', 'skew_ppm': c.skew_ppm if c else '',
        'anchor_ns': c.anchor_ns if c else '', 'prior_ns': '' if s.prior_ns is None else s.prior_ns,
        'cost': s.cost, 'confidence': s.confidence, 'windows_tried': s.windows_tried,
        'windows_accepted': s.windows_accepted,
        'window_start_ns': '' if s.window_ns is None else s.window_ns[0],
        'window_end_ns': '' if s.window_ns is None else s.window_ns[1],
        'uncertainty_ns': '' if s.uncertainty_ns is None else f'{s.uncertainty_ns:.0f}',
        'skew_uncertainty_ppm': '' if s.skew_uncertainty_ppm is None else f'{s.skew_uncertainty_ppm:.3f}',
        'reason': s.reason, 'jumps': s.jumps, 'events': s.events,
        'events_per_s': rate, 'far_events': s.far_events, 'messages_in': path.received,
        'messages_out': path.published, 'messages_lost': path.messages_lost, 'late_callbacks': s.late_messages,
        'malformed': path.malformed, 'unrestamped': path.unrestamped, 'duplicates': path.duplicates,
        'out_of_order': path.out_of_order, 'held': path.held, 'bins_bytes': s.bins_bytes,
        'released_unshifted': path.released_unshifted,
        'silent_s': '' if s.silent_ns is None else f'{s.silent_ns / 1e9:.3f}',
        'latency_p50_us': f'{path.latency_p50_us:.1f}', 'latency_p99_us': f'{path.latency_p99_us:.1f}',
        'envelope_latency_us': f'{envelope_latency_ns / 1e3:g}',
        'decoder_anomalies': path.decoder_anomalies,
        'seeds_replaced': s.seeds_replaced, 'frozen': s.frozen, 'estimator_restarts': health.estimator_restarts,
        'publishers': _endpoints(path.publishers), 'subscribers': _endpoints(path.subscribers),
        'trigger_edges': s.edges, 'trigger_tied_to': s.tied_to,
        'density_minus_edges_us': '' if s.density_offset_ns is None or c is None else
        f'{(s.density_offset_ns - c.offset_ns) / 1e3:+.1f}',
    }
    return DiagnosticStatus(level=level, name=f'evsync: {topic}', message=message, hardware_id=topic,
                            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])


def _level(path: PathCounters, s: Status, marks: Marks, health: Health) -> tuple[bytes, str]:
    """A stream's level and message, before its camera process's state is taken into account."""
    level, message = DiagnosticStatus.OK, s.message
    if s.state in (State.ESTIMATING, State.LOST):
        level = DiagnosticStatus.WARN
    if s.state is State.WAITING and health.silent_start:
        level, message = DiagnosticStatus.ERROR, f'no events after {(health.now_ns - health.started_ns) / 1e9:.0f} s'
    if path.malformed or path.unrestamped:
        level = max(level, DiagnosticStatus.WARN)
        message += f'; {path.malformed + path.unrestamped} bad messages (last: {path.last_error})'
    if path.messages_lost > marks.lost:
        level = max(level, DiagnosticStatus.WARN)
        message += f'; {path.messages_lost - marks.lost} messages lost upstream since the last report (seq gaps)'
    if s.late_messages:
        message += f'; {s.late_messages} messages came late'
    if s.seeds_replaced > marks.seeds:  # a saved offset was wrong: the rig changed, or it is another rig's
        level = max(level, DiagnosticStatus.WARN)
        message += '; the saved offset disagreed with the estimate and was replaced'
    if health.estimator_restarts > marks.restarts:  # a new estimator process took over
        level = max(level, DiagnosticStatus.WARN)
        message += f'; {estimator_restarted(health.estimator_restarts)}'
    if s.frozen:
        message += '; frozen (corrections kept, not updated)'
    if path.duplicates:
        message += f'; {path.duplicates} duplicate messages dropped'
    if path.out_of_order:
        message += f'; {path.out_of_order} messages out of order'
    if health.worker_error is not None:
        level, message = DiagnosticStatus.ERROR, f'estimation stopped: {health.worker_error!r}'
    return level, message


def companion_diagnostic(topic: str, camera: str, output: str, c: CompanionCounters, camera_state: State
                         ) -> DiagnosticStatus:
    """A companion's status: OK once its camera is locked, WARN before, or after malformed messages."""
    d = DiagnosticStatus()
    d.name = f'evsync: companion {topic}'
    d.hardware_id = topic
    if c.malformed:
        d.level, d.message = DiagnosticStatus.WARN, f'{c.malformed} messages not restamped: {c.last_error}'
    elif c.stamps_disagreeing:
        d.level, d.message = DiagnosticStatus.WARN, c.stamps_said
    elif camera_state is State.LOCKED:
        d.level, d.message = DiagnosticStatus.OK, f'restamped with {camera}'
    else:
        d.level, d.message = DiagnosticStatus.WARN, f'{camera} is {camera_state.value}'
    values = {'camera': camera, 'output': output, 'messages_in': c.received, 'messages_out': c.published,
              'malformed': c.malformed, 'held': c.held, 'released_unshifted': c.released_unshifted,
              'offset_ns': '' if c.offset_ns is None else c.offset_ns, 'stamps_checked': c.stamps_checked,
              'stamps_disagreeing': c.stamps_disagreeing, 'stamp_worst_ns': c.stamp_worst_ns,
              'packet_period_ns': c.packet_period_ns, 'publishers': _endpoints(c.publishers),
              'subscribers': _endpoints(c.subscribers)}
    d.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    return d


def host_diagnostic(fit: HostFit | None, why: str) -> DiagnosticStatus:
    """``reference: host``: the line of the cameras' timeline onto host time (WARN until fitted)."""
    d = DiagnosticStatus()
    d.name, d.hardware_id = 'evsync: host', 'host'
    if fit is None:
        d.level, d.message = DiagnosticStatus.WARN, f'not on host time yet: {why or "no camera locked"}'
        return d
    d.level, d.message = DiagnosticStatus.OK, 'on host time'
    d.values = [KeyValue(key=k, value=str(v)) for k, v in fit.as_json().items()]
    return d


def _endpoints(count: int | None) -> int | str:
    return '' if count is None else count


def time_msg(ns: int) -> Time:
    """A builtin_interfaces/Time from int ns."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
