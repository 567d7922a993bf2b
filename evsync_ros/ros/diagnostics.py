"""What the node knows of each stream, and how /diagnostics and /evsync/offsets report it.

``StreamState`` is one stream's message path (its decoder, restamper, publisher, held messages)
and its counters; ``stream_diagnostic`` makes its ``DiagnosticStatus`` from them and the online
estimate's ``Status``.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from evsync_ros.bag.stampcheck import CameraTimes, StampCheck
from evsync_ros.core.engine import State, Status
from evsync_ros.core.host import HostFit
from msg_adapters.protocols import Decoder
from msg_adapters.registry import Restamper

LATENCY_SAMPLES = 4096
"""Receipt-to-publish times kept per stream for the percentiles in /diagnostics."""
RECENT_MESSAGES = 256
"""Messages per stream remembered to recognise one delivered twice."""
DUPLICATE_BYTES = 512
"""A message is known by its length, header.stamp, and its first and last this many bytes (which hold
its first and last events' times): two different event messages never share all of them."""


@dataclass
class StreamState:
    topic: str
    output: str
    decoder: Decoder
    restamper: Restamper
    msgtype: str = ''
    model: str = ''
    """What tells its camera model apart (``registry.camera_model`` of its first decoded message)."""
    publisher: Any = None
    """The stream's rclpy publisher of raw messages."""
    subscription: Any = None
    """Its rclpy subscription to the camera's topic (in the process that takes its messages)."""
    held: deque[tuple[int, bytes]] = field(default_factory=deque)
    """(arrival time, message) of messages held until the lock (``before_lock: hold``)."""
    received: int = 0
    published: int = 0
    malformed: int = 0
    unrestamped: int = 0
    released_unshifted: int = 0
    last_error: str = ''
    latency_ns: np.ndarray = field(default_factory=lambda: np.zeros(LATENCY_SAMPLES, np.int64))
    latency_count: int = 0
    last_time_ns: int | None = None
    """Newest decoded event time (the camera's timeline)."""
    duplicates: int = 0
    """Messages identical to one of the last ``RECENT_MESSAGES`` (delivered twice): counted, dropped."""
    out_of_order: int = 0
    """Messages whose header.stamp is before the previous message's: counted, published as they came."""
    last_stamp: bytes = b''
    lost_mark: int = 0
    """Messages lost upstream (seq gaps) at the last report: WARN while the count grows."""
    seeds_mark: int = 0
    """Saved offsets replaced at the last report: WARN in the report that sees one more."""
    restarts_mark: int = 0
    """Estimator processes started again at the last report: WARN in the report that sees one more."""
    rate_mark: tuple[int, int] | None = None
    """(arrival time, events) at the last report: the event rate since."""
    times: CameraTimes = field(default_factory=CameraTimes)
    """Newest event time and packet period, for its companions' stamp check."""
    recent: deque[tuple[int, bytes, int, int]] = field(default_factory=lambda: deque(maxlen=RECENT_MESSAGES))
    recent_keys: set[tuple[int, bytes, int, int]] = field(default_factory=set)

    def seen(self, raw: bytes) -> bool:
        """Whether ``raw`` is one of the last messages again; it is remembered either way."""
        key = (len(raw), raw[4:12], hash(raw[:DUPLICATE_BYTES]), hash(raw[-DUPLICATE_BYTES:]))
        if key in self.recent_keys:
            return True
        if len(self.recent) == self.recent.maxlen:
            self.recent_keys.discard(self.recent[0])
        self.recent.append(key)
        self.recent_keys.add(key)
        return False


@dataclass
class CompanionState:
    """A companion topic's message path (its camera's correction on header.stamp) and counters."""

    topic: str
    camera: str
    output: str
    publisher: Any = None
    subscription: Any = None
    held: deque[tuple[int, bytes]] = field(default_factory=deque)
    """(arrival time, message) held until its camera's lock (``before_lock: hold``, or ``coarse``
    before the reference has sent anything)."""
    received: int = 0
    published: int = 0
    malformed: int = 0
    """Messages that could not be restamped (too short, not CDR ...): published unchanged, counted."""
    released_unshifted: int = 0
    applied: Any = None
    """The correction the newest published message got."""
    last_error: str = ''
    stamps: StampCheck = field(init=False)
    """Its stamps against its camera's event times (an old driver's wrong stamps)."""

    def __post_init__(self) -> None:
        self.stamps = StampCheck(self.topic, self.camera)


COMPANION_COUNTERS = ('received', 'published', 'malformed', 'released_unshifted', 'last_error')


def companion_values(cs: CompanionState) -> dict[str, Any]:
    """A companion's counters, held messages and the offset it last got: what a camera process sends
    the estimator process for ``companion_diagnostic``."""
    values: dict[str, Any] = {name: getattr(cs, name) for name in COMPANION_COUNTERS}
    values.update(held=len(cs.held), offset_ns='' if cs.applied is None else str(cs.applied.offset_ns),
                  stamps=cs.stamps.as_json(), **matched(cs))
    return values


def matched(state: StreamState | CompanionState) -> dict[str, int | str]:
    """The DDS endpoints a stream's message path is connected to: ``publishers`` its subscription has
    matched (its camera driver, a player), ``subscribers`` its output has ('' where it has none)."""
    return {'publishers': '' if state.subscription is None else state.subscription.get_publisher_count(),
            'subscribers': '' if state.publisher is None else state.publisher.get_subscription_count()}


def companion_diagnostic(cs: CompanionState, camera_state: State, path: dict[str, Any] | None = None
                         ) -> DiagnosticStatus:
    """A companion's status: OK once its camera is locked, WARN before, or after malformed messages.
    ``path``: its values as its camera process reported them (``companion_values``; default: ``cs``'s)."""
    if path is not None:
        for name in COMPANION_COUNTERS:
            setattr(cs, name, path[name])
        for name in ('checked', 'disagreeing', 'worst_ns', 'period_ns'):
            setattr(cs.stamps, name, path['stamps'][name])
    else:
        path = companion_values(cs)
    d = DiagnosticStatus()
    d.name = f'evsync: companion {cs.topic}'
    d.hardware_id = cs.topic
    if cs.malformed:
        d.level, d.message = DiagnosticStatus.WARN, f'{cs.malformed} messages not restamped: {cs.last_error}'
    elif cs.stamps.disagreeing:
        d.level, d.message = DiagnosticStatus.WARN, cs.stamps.says()
    elif camera_state is State.LOCKED:
        d.level, d.message = DiagnosticStatus.OK, f'restamped with {cs.camera}'
    else:
        d.level, d.message = DiagnosticStatus.WARN, f'{cs.camera} is {camera_state.value}'
    values = {'camera': cs.camera, 'output': cs.output, 'messages_in': cs.received, 'messages_out': cs.published,
              'malformed': cs.malformed, 'held': path['held'], 'released_unshifted': cs.released_unshifted,
              'offset_ns': path['offset_ns'], 'stamps_checked': cs.stamps.checked,
              'stamps_disagreeing': cs.stamps.disagreeing, 'stamp_worst_ns': cs.stamps.worst_ns,
              'packet_period_ns': cs.stamps.period_ns, 'publishers': path['publishers'],
              'subscribers': path['subscribers']}
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


PATH_COUNTERS = ('received', 'published', 'malformed', 'unrestamped', 'released_unshifted', 'duplicates',
                 'out_of_order', 'last_error', 'last_time_ns')
"""The ``StreamState`` counters a camera process reports to its estimator (``path_values``)."""


def path_values(st: StreamState) -> dict[str, Any]:
    """What a stream's message path knows (its counters, held messages, losses upstream, receipt-to-
    publish percentiles, decoder anomalies): what a camera process sends the estimator process, and
    what ``stream_diagnostic`` reports."""
    n = min(st.latency_count, LATENCY_SAMPLES)
    lat = np.percentile(st.latency_ns[:n], [50, 99]) / 1e3 if n else (float('nan'), float('nan'))
    values: dict[str, Any] = {name: getattr(st, name) for name in PATH_COUNTERS}
    values.update(held=len(st.held), messages_lost=messages_lost(st.decoder), latency_p50_us=f'{lat[0]:.1f}',
                  latency_p99_us=f'{lat[1]:.1f}',
                  decoder_anomalies='; '.join(f'{k}: {v}' for k, v in getattr(st.decoder, 'anomalies', {}).items()),
                  **matched(st))
    return values


def estimator_restarted(restarts: int) -> str:
    """What the log and /diagnostics say when an estimator process died and a new one took over."""
    return f'the estimator process died and was started again ({restarts} so far)'


def stream_diagnostic(st: StreamState, s: Status, *, now_ns: int, silent_start: bool, started_ns: int,
                      worker_error: BaseException | None, envelope_latency_ns: int,
                      path: dict[str, Any] | None = None, process_error: str = '',
                      estimator_restarts: int = 0) -> DiagnosticStatus:
    """One stream's status: OK locked, WARN estimating, lost or bad messages, an estimator process
    started again since the last report (``estimator_restarts``, the node's count), ERROR no events
    since the start (``silent_start``), the estimator stopped (``worker_error``) or the stream's
    camera process did (``process_error``); every counter as a value. ``path``: the message path's
    values as its camera process reported them (``path_values``; default: ``st``'s own)."""
    now = now_ns
    if path is not None:
        for name in PATH_COUNTERS:
            setattr(st, name, path[name])
    else:
        path = path_values(st)
    level, message = DiagnosticStatus.OK, s.message
    if s.state in (State.ESTIMATING, State.LOST):
        level = DiagnosticStatus.WARN
    if s.state is State.WAITING and silent_start:
        level, message = DiagnosticStatus.ERROR, f'no events after {(now - started_ns) / 1e9:.0f} s'
    if st.malformed or st.unrestamped:
        level = max(level, DiagnosticStatus.WARN)
        message += f'; {st.malformed + st.unrestamped} bad messages (last: {st.last_error})'
    lost = int(path['messages_lost'])
    if lost > st.lost_mark:
        level = max(level, DiagnosticStatus.WARN)
        message += f'; {lost - st.lost_mark} messages lost upstream since the last report (seq gaps)'
    st.lost_mark = lost
    if s.late_messages:
        message += f'; {s.late_messages} messages came late'
    if s.seeds_replaced > st.seeds_mark:  # a saved offset was wrong: the rig changed, or it is another rig's
        level = max(level, DiagnosticStatus.WARN)
        message += '; the saved offset disagreed with the estimate and was replaced'
    st.seeds_mark = s.seeds_replaced
    if estimator_restarts > st.restarts_mark:  # a new estimator process took over
        level = max(level, DiagnosticStatus.WARN)
        message += f'; {estimator_restarted(estimator_restarts)}'
    st.restarts_mark = estimator_restarts
    if s.frozen:
        message += '; frozen (corrections kept, not updated)'
    if st.duplicates:
        message += f'; {st.duplicates} duplicate messages dropped'
    if st.out_of_order:
        message += f'; {st.out_of_order} messages out of order'
    if worker_error is not None:
        level, message = DiagnosticStatus.ERROR, f'estimation stopped: {worker_error!r}'
    if process_error:
        level, message = DiagnosticStatus.ERROR, process_error
    c = s.correction
    rate = ''
    if st.rate_mark is not None and now > st.rate_mark[0]:
        rate = f'{max(0, s.events - st.rate_mark[1]) * 1e9 / (now - st.rate_mark[0]):.0f}'
    st.rate_mark = (now, s.events)
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
        'events_per_s': rate, 'far_events': s.far_events, 'messages_in': st.received, 'messages_out': st.published,
        'messages_lost': lost, 'late_callbacks': s.late_messages,
        'malformed': st.malformed, 'unrestamped': st.unrestamped, 'duplicates': st.duplicates,
        'out_of_order': st.out_of_order, 'held': path['held'], 'bins_bytes': s.bins_bytes,
        'released_unshifted': st.released_unshifted,
        'silent_s': '' if s.silent_ns is None else f'{s.silent_ns / 1e9:.3f}',
        'latency_p50_us': path['latency_p50_us'], 'latency_p99_us': path['latency_p99_us'],
        'envelope_latency_us': f'{envelope_latency_ns / 1e3:g}',
        'decoder_anomalies': path['decoder_anomalies'],
        'seeds_replaced': s.seeds_replaced, 'frozen': s.frozen, 'estimator_restarts': estimator_restarts,
        'publishers': path['publishers'], 'subscribers': path['subscribers'],
    }
    return DiagnosticStatus(level=level, name=f'evsync: {st.topic}', message=message, hardware_id=st.topic,
                            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])


def messages_lost(decoder: Decoder) -> int:
    """Messages of a stream lost before the node (EventPacket seq gaps; 0 for types without seq)."""
    return int(getattr(decoder, 'lost', 0))


def time_msg(ns: int) -> Time:
    """A builtin_interfaces/Time from int ns."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
