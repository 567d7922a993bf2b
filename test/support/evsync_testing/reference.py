"""Plain-Python decoders written straight from the format descriptions: the oracle the tests check
the C word loops against, and the naive baseline of ``bench/adapters.py``. Slow on purpose: one
Python step per word, no state shared with the decoders under test."""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterable

import numpy as np

Event = tuple[int, int, int, int]
"""(time ns, x, y, polarity)."""
Edge = tuple[int, int, int]
"""(time ns, edge value, channel id) of a trigger edge."""
REANCHOR_NS = 1_000_000_000


def evt3_reference_decode(payloads: Iterable[bytes], width: int, height: int) -> list[Event]:
    """Word by word, as the evt3 format describes; state carried across payloads."""
    out: list[Event] = []
    th = tl = -1
    wraps = y = base_x = pol = 0
    valid = False
    for payload in payloads:
        for w in np.frombuffer(bytes(payload), dtype='<u2').tolist():
            typ, v = w >> 12, w & 0xFFF
            if typ == 0x8:
                if th >= 0 and th - v > 10:
                    wraps += 1
                th = v
            elif typ == 0x6:
                tl = v
                valid = valid or th >= 0
            elif typ == 0x0:
                y = v & 0x7FF
            elif typ == 0x3:
                base_x, pol = v & 0x7FF, v >> 11
            elif typ in (0x2, 0x4, 0x5):
                t = ((wraps << 24) | (th << 12) | tl) * 1000
                if typ == 0x2:
                    hits = [(v & 0x7FF, v >> 11)]
                else:
                    size = 12 if typ == 0x4 else 8
                    hits = [(base_x + i, pol) for i in range(size) if v >> i & 1]
                    base_x += size
                if valid:
                    out += [(t, x, y, p) for x, p in hits if x < width and y < height]
    return out


def evt3_reference_edges(packets: Iterable[tuple[int, bytes]], width: int, height: int) -> list[Edge]:
    """The EXT_TRIGGER edges of an evt3 stream, given as (header.stamp ns, payload) per message in
    stream order, word by word as the format describes, on the timeline its events decode to.

    EXT_TRIGGER (type 0xA): edge value bit 0, channel bits 8-11, at the current time; none before the
    stream's first TIME_HIGH then TIME_LOW (as no event). Timeline: sensor time plus an anchor, header.stamp minus
    the sensor time of the message's first event (inside the geometry), taken at the first message
    with one and taken again where a later message's differs by more than a second; a message's
    edges take the anchor after its own first event, and edges before any anchor are left out."""
    out: list[Edge] = []
    th = tl = -1
    wraps = y = base_x = 0
    valid = False
    anchor: int | None = None
    for stamp, payload in packets:
        first_event: int | None = None
        edges: list[Edge] = []
        for w in np.frombuffer(bytes(payload), dtype='<u2').tolist():
            typ, v = w >> 12, w & 0xFFF
            t = ((wraps << 24) | (max(th, 0) << 12) | max(tl, 0)) * 1000
            if typ == 0x8:
                if th >= 0 and th - v > 10:
                    wraps += 1
                th = v
            elif typ == 0x6:
                tl = v
                valid = valid or th >= 0
            elif typ == 0x0:
                y = v & 0x7FF
            elif typ == 0x3:
                base_x = v & 0x7FF
            elif typ == 0xA and valid:
                edges.append((t, v & 1, (v >> 8) & 0xF))
            elif typ in (0x2, 0x4, 0x5):
                xs = [v & 0x7FF] if typ == 0x2 else [base_x + i for i in range(12 if typ == 0x4 else 8) if v >> i & 1]
                if typ != 0x2:
                    base_x += 12 if typ == 0x4 else 8
                if valid and first_event is None and any(x < width for x in xs) and y < height:
                    first_event = t
        if first_event is not None and (anchor is None or abs(stamp - first_event - anchor) > REANCHOR_NS):
            anchor = stamp - first_event
        if anchor is not None:
            out += [(t + anchor, value, channel) for t, value, channel in edges]
    return out


def trigger_reference_edges(packets: Iterable[tuple[int, bytes]]) -> list[Edge]:
    """The edges of ``trigger`` payloads, given as (time_base ns, payload) per message: one uint64 per
    edge, bit 63 the value, bits 48-62 the channel, bits 0-31 dt in ns after time_base."""
    out: list[Edge] = []
    for time_base, payload in packets:
        data = bytes(payload)
        for (word,) in struct.iter_unpack('<Q', data[: len(data) - len(data) % 8]):
            out.append((time_base + (word & 0xFFFFFFFF), word >> 63, (word >> 48) & 0x7FFF))
    return out


def libcaer_cmp_reference_decode(packets: Iterable[tuple[bytes, int]], width: int, height: int) -> list[Event]:
    """Word by word, as the libcaer_cmp format describes: (t, x, y, p) per event."""
    out: list[Event] = []
    x = base_y = pol = 0
    for payload, time_base in packets:
        high = low = 0
        for w in np.frombuffer(bytes(payload), dtype='<u2').tolist():
            code, v = w >> 12, w & 0xFFF
            t = ((high << 12) | low) * 1000 + time_base
            if code == 0:
                high = v
            elif code == 1:
                low = v
            elif code == 2:
                x = v & 0x7FF
            elif code == 3:
                if x < width and (v & 0x7FF) < height:
                    out.append((t, x, v & 0x7FF, v >> 11))
            elif code == 4:
                base_y, pol = v & 0x7FF, v >> 11
            elif code == 5:
                out += [(t, x, base_y + i, pol) for i in range(8) if v >> i & 1 and x < width and base_y + i < height]
                base_y += 8
    return out


class ReferenceRetimer:
    """``msg_adapters.evt3.Evt3Retimer`` in numpy, word arrays at a time: the oracle its C walk is
    checked against. Rewrites one stream's evt3 time words so that sensor time u reads
    u + round(k (u - u0)) (or u + shift_us(u)).

    k is ``skew_ppm`` * 1e-6 and u0 the stream's first valid time: a clock skew carried into the
    payload itself, which decoders that anchor evt3 sensor time once (ours, event_camera_codecs)
    then see. Each valid TIME_HIGH or TIME_LOW word becomes a TIME_LOW of the corrected time,
    preceded by a TIME_HIGH where the corrected high part changes, so every event word keeps its
    place and takes the corrected time of the state it had; each payload's first time word writes
    its high part. Words before the stream's first valid time are copied. Like the decoder, the
    state (high, low, wraps) carries from one message to the next, so messages must come in
    stream order.
    """

    def __init__(self, skew_ppm: float) -> None:
        self.k = skew_ppm * 1e-6
        self.high = -1
        self.low = -1
        self.wraps = 0
        self.low_u = -1
        """Unwrapped time at the last TIME_LOW (-1: none yet)."""
        self.u0: int | None = None

    def retime(self, payload: np.ndarray | bytes | memoryview, *,
               shift_us: Callable[[np.ndarray], np.ndarray] | None = None) -> bytes:
        """The payload with its time words rewritten. ``shift_us`` (optional) maps the payload's
        unwrapped valid times u (int64 us, in order) to what to add to each, in place of the skew;
        a payload whose shifts are all zero comes back unchanged (the state still moves on)."""
        words = np.frombuffer(payload, '<u2', count=len(payload) // 2)
        kind = words >> 12
        at = np.flatnonzero((kind == 0x6) | (kind == 0x8))
        if at.size == 0:
            return bytes(payload)
        is_high = kind[at] == 0x8
        value = (words[at] & 0xFFF).astype(np.int64)
        high = _carried(np.where(is_high, value, -1), self.high)
        low = _carried(np.where(is_high, -1, value), self.low)
        before = np.concatenate([[self.high], high[:-1]])
        wrapped = is_high & (before >= 0) & (high < before - 10)
        wraps = self.wraps + np.cumsum(wrapped)
        valid = (high >= 0) & (low >= 0)
        # A TIME_HIGH that no event word follows (the next word is a time word, or the payload ends)
        # only moves the high part on: it is written as a TIME_HIGH alone, and only when the corrected
        # high part changes, so the highs written never step back. One that events follow gives
        # them its full state.
        nxt = np.minimum(at + 1, words.size - 1)
        events_follow = (at + 1 < words.size) & (kind[nxt] != 0x6) & (kind[nxt] != 0x8)
        high_only = is_high & ~events_follow
        u = ((high << 12) | np.maximum(low, 0)) + (wraps << 24)
        # such a TIME_HIGH stands for the later of its high part's start and the last TIME_LOW's time
        # (the low the decoder holds may be left from the high part before: a state no event sees)
        at_low = ~is_high & valid
        last_low = _carried(np.where(at_low, np.arange(at.size), -1), -1)
        previous_low = np.concatenate([[-1], last_low[:-1]])
        low_time = np.where(previous_low >= 0, u[np.maximum(previous_low, 0)], self.low_u)
        u = np.where(high_only, np.maximum((high << 12) + (wraps << 24), low_time), u)
        if self.u0 is None and valid.any():
            self.u0 = int(u[valid][0])
        self.high, self.low, self.wraps = int(high[-1]), int(low[-1]), int(wraps[-1])
        if at_low.any():
            self.low_u = int(u[np.flatnonzero(at_low)[-1]])
        if not valid.any():
            return bytes(payload)
        at, u, high_only = at[valid], u[valid], high_only[valid]
        shift = shift_us(u) if shift_us is not None else np.rint(self.k * (u - self.u0)).astype(np.int64)
        if not shift.any():
            return bytes(payload)
        new = u + shift
        new_high, new_low = (new >> 12) & 0xFFF, new & 0xFFF
        previous = np.concatenate([[-1], new_high[:-1]])  # each payload states its high part first
        need_high = new_high != previous
        count = np.ones(words.size, np.int64)
        count[at] = np.where(high_only, need_high, 1 + need_high)
        pos = np.cumsum(count) - 1
        out = np.empty(int(pos[-1]) + 1, np.uint16)
        plain = count == 1
        plain[at] = False
        out[pos[plain]] = words[plain]
        with_low = ~high_only
        out[pos[at][with_low]] = (0x6 << 12) | new_low[with_low]
        high_at = np.where(high_only, pos[at], pos[at] - 1)
        out[high_at[need_high]] = (0x8 << 12) | new_high[need_high]
        return out.astype('<u2').tobytes() + bytes(payload)[2 * words.size:]


def _carried(values: np.ndarray, initial: int) -> np.ndarray:
    """Each place's latest value >= 0 so far (forward fill), ``initial`` before the first."""
    idx = np.where(values >= 0, np.arange(values.size), -1)
    np.maximum.accumulate(idx, out=idx)
    return np.where(idx >= 0, values[np.maximum(idx, 0)], initial)
