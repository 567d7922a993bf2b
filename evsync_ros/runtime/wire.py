"""The wire form of ``core.counts.MessageBins``: what a camera process (``processes: per_camera``)
sends the node, a flat int64 array."""

from __future__ import annotations

import numpy as np

from evsync_ros.core.counts import MessageBins
from evsync_ros.core.errors import StreamError

__all__ = ['WIRE_VERSION', 'pack', 'unpack']

WIRE_VERSION = 1
NONE = np.iinfo(np.int64).min
"""A missing time in the wire form (no host pair)."""
_FIXED = 7
"""Fields of a record before its bins: receipt, mid, lo, hi, host event, host time, bins."""


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
