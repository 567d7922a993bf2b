"""What a camera process (``processes: per_camera``) and ``evsync_node`` send each other, in one
place: a batch of ``core.counts.MessageBins`` (a flat int64 array), the corrections the estimator
publishes for every camera, and a camera process's report of its message path (JSON, in a
std_msgs/String). Each ``decode`` raises StreamError naming its source when what came is not one
(another version, a field missing or of the wrong type): the receiver counts it and goes on."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from typing import Any, TypeVar

import numpy as np

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.counts import MessageBins
from evsync_ros.core.engine import State
from evsync_ros.core.errors import EvsyncError, StreamError

__all__ = ['WIRE_VERSION', 'CameraCorrection', 'CameraReport', 'CompanionCounters', 'PathCounters',
           'decode_corrections', 'decode_report', 'encode_corrections', 'encode_report', 'pack', 'unpack']

WIRE_VERSION = 1
NONE = np.iinfo(np.int64).min
"""A missing time in the counts' wire form (no host pair)."""
_FIXED = 7
"""Fields of a record before its bins: receipt, mid, lo, hi, host event, host time, bins."""
R = TypeVar('R')


def pack(messages: list[MessageBins], *, camera: int) -> np.ndarray:
    """The wire form of a batch of one camera's messages (``camera``: its index in ``topics``):
    [version, camera, n, then per message receipt, mid, lo, hi, host event, host time, k, k bins,
    k counts]."""
    parts: list[np.ndarray] = [np.array([WIRE_VERSION, camera, len(messages)], np.int64)]
    for m in messages:
        head = [m.receipt_ns, m.mid_ns, m.lo_ns, m.hi_ns,
                NONE if m.host_event_ns is None else m.host_event_ns, NONE if m.host_ns is None else m.host_ns,
                m.bins.size]
        parts += [np.array(head, np.int64), m.bins, m.counts]
    return np.concatenate(parts)


def unpack(data: np.ndarray, *, source: str) -> tuple[int, list[MessageBins]]:
    """(camera index, messages) of a batch in wire form; StreamError naming ``source`` when it is
    not one (another version, truncated, bins not ascending, negative counts)."""
    data = np.asarray(data, np.int64)

    def bad(why: str) -> StreamError:
        return StreamError(f'{source}: not an evsync counts batch: {why}')

    if data.size < 3 or int(data[0]) != WIRE_VERSION:
        raise bad(f'version {int(data[0]) if data.size else None}, expected {WIRE_VERSION}')
    camera, n = int(data[1]), int(data[2])
    if n < 0:
        raise bad(f'{n} messages')
    out: list[MessageBins] = []
    i = 3
    for j in range(n):
        if i + _FIXED > data.size:
            raise bad(f'message {j} truncated')
        receipt, mid, lo, hi, host_event, host, k = (int(x) for x in data[i:i + _FIXED])
        i += _FIXED
        if k < 0 or i + 2 * k > data.size:
            raise bad(f'message {j}: {k} bins')
        bins, counts = data[i:i + k].copy(), data[i + k:i + 2 * k].copy()
        i += 2 * k
        if k and (np.any(np.diff(bins) <= 0) or np.any(counts <= 0)):
            raise bad(f'message {j}: bins not ascending or counts not positive')
        out.append(MessageBins(receipt, mid, lo, hi, bins, counts, None if host_event == NONE else host_event,
                               None if host == NONE else host))
    if i != data.size:
        raise bad(f'{data.size - i} values after the last message')
    return camera, out


# --- corrections: the estimator to every camera process (latched) ----------------------------------

@dataclass(frozen=True)
class CameraCorrection:
    """What a camera's messages get now, as the estimator sees it."""

    state: State
    prior_ns: int | None
    """The offset seen in arrival times (``before_lock: coarse``; None while not known)."""
    correction: ClockCorrection | None
    """None: not locked (its messages get what ``before_lock`` says)."""


def encode_corrections(corrections: Mapping[str, CameraCorrection]) -> str:
    """Every camera's correction, by topic."""
    return json.dumps({'version': WIRE_VERSION, 'cameras': {
        topic: {'state': c.state.value, 'prior_ns': c.prior_ns,
                'correction': None if c.correction is None else asdict(c.correction)}
        for topic, c in corrections.items()}})


def decode_corrections(text: str, *, source: str) -> dict[str, CameraCorrection]:
    """``encode_corrections``' form back (StreamError naming ``source`` when it is not one)."""
    doc = _document(text, source, 'corrections')
    try:
        out = {}
        for topic, c in doc['cameras'].items():
            given = c['correction']
            correction = None if given is None else ClockCorrection(
                offset_ns=_int(given['offset_ns']), skew_ppm=float(given['skew_ppm']),
                anchor_ns=_int(given['anchor_ns']))
            prior = None if c['prior_ns'] is None else _int(c['prior_ns'])
            out[str(topic)] = CameraCorrection(State(c['state']), prior, correction)
        return out
    except (KeyError, TypeError, ValueError, AttributeError, EvsyncError) as exc:
        raise StreamError(f'{source}: not evsync corrections: {exc!r}') from None


# --- a camera process's report of its message path (every diagnostics period) ---------------------

@dataclass(frozen=True)
class PathCounters:
    """A stream's message path as /diagnostics reports it."""

    received: int = 0
    published: int = 0
    malformed: int = 0
    """Messages that could not be decoded: published unchanged, counted."""
    unrestamped: int = 0
    """Messages that could not be restamped: published unchanged, counted."""
    released_unshifted: int = 0
    """Held past ``hold_limit_s``: published unshifted."""
    duplicates: int = 0
    out_of_order: int = 0
    last_error: str = ''
    last_time_ns: int | None = None
    """Its newest decoded event time (the camera's timeline)."""
    held: int = 0
    messages_lost: int = 0
    """Lost before the node (EventPacket seq gaps)."""
    latency_p50_us: float = math.nan
    latency_p99_us: float = math.nan
    """Receipt to publish, over the newest messages."""
    decoder_anomalies: str = ''
    publishers: int | None = None
    """Publishers its subscription has matched (None: it has none)."""
    subscribers: int | None = None
    """Subscribers its output has matched (None: it has none)."""


@dataclass(frozen=True)
class CompanionCounters:
    """A companion's message path as /diagnostics reports it."""

    received: int = 0
    published: int = 0
    malformed: int = 0
    released_unshifted: int = 0
    last_error: str = ''
    held: int = 0
    offset_ns: int | None = None
    """The offset its newest published message got (None: none yet)."""
    stamps_checked: int = 0
    stamps_disagreeing: int = 0
    stamp_worst_ns: int = 0
    packet_period_ns: int = 0
    stamps_said: str = ''
    """The stamp check's warning ('' while every stamp agrees)."""
    publishers: int | None = None
    subscribers: int | None = None


@dataclass(frozen=True)
class CameraReport:
    """One camera process's stream and its companions, by topic."""

    topic: str
    path: PathCounters
    companions: dict[str, CompanionCounters]


def encode_report(report: CameraReport) -> str:
    return json.dumps({'version': WIRE_VERSION, 'topic': report.topic, 'path': asdict(report.path),
                       'companions': {t: asdict(c) for t, c in report.companions.items()}})


def decode_report(text: str, *, source: str) -> CameraReport:
    """``encode_report``'s form back (StreamError naming ``source`` when it is not one)."""
    doc = _document(text, source, 'camera report')
    try:
        return CameraReport(str(doc['topic']), _record(PathCounters, doc['path']),
                            {str(t): _record(CompanionCounters, c) for t, c in doc['companions'].items()})
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise StreamError(f'{source}: not an evsync camera report: {exc!r}') from None


def _document(text: str, source: str, what: str) -> dict[str, Any]:
    try:
        doc = json.loads(text)
    except ValueError as exc:
        raise StreamError(f'{source}: not evsync {what}: {exc}') from None
    if not isinstance(doc, dict) or doc.get('version') != WIRE_VERSION:
        version = doc.get('version') if isinstance(doc, dict) else None
        raise StreamError(f'{source}: not evsync {what}: version {version!r}, expected {WIRE_VERSION}')
    return doc


_TYPES: dict[str, tuple[type, ...]] = {'int': (int,), 'str': (str,), 'float': (float, int),
                                       'int | None': (int, type(None))}


def _record(cls: type[R], values: Mapping[str, Any]) -> R:
    """A counters record from its JSON, every field there and of its type."""
    kwargs = {}
    for f in fields(cls):  # type: ignore[arg-type]
        value = values[f.name]
        if not isinstance(value, _TYPES[str(f.type)]) or isinstance(value, bool):
            raise TypeError(f'{f.name}: {value!r} is not {f.type}')
        kwargs[f.name] = value
    return cls(**kwargs)


def _int(value: Any) -> int:
    if not isinstance(value, int) or isinstance(value, bool):
        raise TypeError(f'{value!r} is not an integer')
    return value
