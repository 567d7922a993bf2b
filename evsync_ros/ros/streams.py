"""What the message path keeps of each stream and companion: its decoder, restamper, publisher,
held messages and counters (``StreamState``, ``CompanionState``), and their counters as reported
(``path_counters``, ``companion_counters``: the wire's records, which a camera process sends)."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from evsync_ros.bag.stampcheck import CameraTimes, StampCheck
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.runtime.wire import CompanionCounters, PathCounters
from msg_adapters.protocols import EdgeDecoder
from msg_adapters.registry import Restamper

__all__ = ['CompanionState', 'StreamState', 'companion_counters', 'path_counters']

LATENCY_SAMPLES = 4096
"""Receipt-to-publish times kept per stream for the percentiles in /diagnostics."""
RECENT_MESSAGES = 256
"""Messages per stream remembered to recognise one delivered twice."""
MESSAGE_BINS = 4096
"""Grid bins one message's events may span to be counted in its C call (``StreamState.counts``):
a message over more (a corrupt time) has its times binned as any message's are."""


@dataclass
class StreamState:
    """One event stream's message path and its counters."""

    topic: str
    output: str
    decoder: EdgeDecoder
    restamper: Restamper
    msgtype: str = ''
    model: str = ''
    """What tells its camera model apart (``registry.camera_model`` of its first decoded message)."""
    trigger_channel: int | None = None
    """The trigger input its shared pulse comes in on (``trigger_channels``); None: its edges are not read."""
    publisher: Any = None
    """The stream's rclpy publisher of raw messages (None: republish none, or another process's)."""
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
    last_stamp: int | None = None
    """header.stamp of its last message (ns; None: none, or too short to hold one)."""
    times: CameraTimes = field(default_factory=CameraTimes)
    """Newest event time and packet period, for its companions' stamp check (``timed``)."""
    timed: bool = False
    """It has a companion: ``times`` is kept (``topics.open_companions``)."""
    recent: deque[int] = field(default_factory=lambda: deque(maxlen=RECENT_MESSAGES))
    recent_keys: set[int] = field(default_factory=set)
    counts: np.ndarray = field(default_factory=lambda: np.zeros(MESSAGE_BINS, np.int32))
    """Where a message decoded in one C call is counted on the estimate's grid (``EventPacketDecoder.step``)."""

    def seen(self, key: int) -> bool:
        """Whether the message of ``key`` (``header.message_key``) is one of the last again; it is
        remembered either way."""
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
    applied: ClockCorrection | None = None
    """The correction the newest published message got."""
    last_error: str = ''
    stamps: StampCheck = field(init=False)
    """Its stamps against its camera's event times (an old driver's wrong stamps)."""

    def __post_init__(self) -> None:
        self.stamps = StampCheck(self.topic, self.camera)


def path_counters(st: StreamState) -> PathCounters:
    """A stream's counters, held messages, losses upstream (EventPacket seq gaps), receipt-to-publish
    percentiles, decoder anomalies and matched endpoints."""
    n = min(st.latency_count, LATENCY_SAMPLES)
    p50, p99 = (float(x) / 1e3 for x in np.percentile(st.latency_ns[:n], [50, 99])) if n else (math.nan, math.nan)
    return PathCounters(
        received=st.received, published=st.published, malformed=st.malformed, unrestamped=st.unrestamped,
        released_unshifted=st.released_unshifted, duplicates=st.duplicates, out_of_order=st.out_of_order,
        last_error=st.last_error, last_time_ns=st.last_time_ns, held=len(st.held),
        messages_lost=int(getattr(st.decoder, 'lost', 0)), latency_p50_us=p50, latency_p99_us=p99,
        decoder_anomalies='; '.join(f'{k}: {v}' for k, v in getattr(st.decoder, 'anomalies', {}).items()),
        publishers=_count(st.subscription, 'get_publisher_count'),
        subscribers=_count(st.publisher, 'get_subscription_count'))


def companion_counters(cs: CompanionState) -> CompanionCounters:
    """A companion's counters, held messages, the offset it last got, its stamp check and endpoints."""
    return CompanionCounters(
        received=cs.received, published=cs.published, malformed=cs.malformed,
        released_unshifted=cs.released_unshifted, last_error=cs.last_error, held=len(cs.held),
        offset_ns=None if cs.applied is None else cs.applied.offset_ns, stamps_checked=cs.stamps.checked,
        stamps_disagreeing=cs.stamps.disagreeing, stamp_worst_ns=cs.stamps.worst_ns,
        packet_period_ns=cs.stamps.period_ns, stamps_said=cs.stamps.says(),
        publishers=_count(cs.subscription, 'get_publisher_count'),
        subscribers=_count(cs.publisher, 'get_subscription_count'))


def _count(endpoint: Any, method: str) -> int | None:
    return None if endpoint is None else int(getattr(endpoint, method)())
