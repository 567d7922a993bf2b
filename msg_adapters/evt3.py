"""Prophesee EVT 3.0 payloads (EventPacket encoding ``evt3``), decoded statefully.

Little-endian 16-bit words, type in the top 4 bits:

    0x0 ADDR_Y       y = bits 0-10
    0x2 ADDR_X       x = bits 0-10, polarity bit 11: one event at the current y and time
    0x3 VECT_BASE_X  base x = bits 0-10, polarity bit 11
    0x4 VECT_12      12-bit mask: an event at base_x + i per set bit i; then base_x += 12
    0x5 VECT_8       8-bit mask, likewise; base_x += 8
    0x6 TIME_LOW     time bits 0-11 (microseconds)
    0x8 TIME_HIGH    time bits 12-23
    0xA EXT_TRIGGER, 0xE OTHERS, 0x7 / 0xF CONTINUED, 0x9 (padding of some cameras): no event

Time is 24 bits of microseconds, wrapping every 16.777216 s. A TIME_HIGH smaller than the one
before by more than 10 counts as a wrap (smaller backward steps happen without one and are
counted as anomalies); wraps are counted in the decoder state, so times stay monotonic across
messages. Events before the stream's first TIME_HIGH-then-TIME_LOW pair have no valid time and
are not emitted, as event_camera_codecs does; events outside the sensor geometry are counted. The
whole state (time high and low, wrap count, y, base x, polarity) carries from one message to the
next. The word loop is C (``msg_adapters/_kernels.c``).

Times are *sensor* time: metavision_driver sets time_base = 0 and the payload alone holds time.
``EventPacketDecoder`` anchors them to ROS time (see ``event_packet.py``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from msg_adapters import _kernels
from msg_adapters.events import Events, WordLoopDecoder


class Evt3Decoder(WordLoopDecoder):
    """Stateful decoder of one stream's evt3 payloads."""

    counter_names = ('unknown word type', 'small backward time step', 'event outside the sensor geometry')
    per_word = 12

    def __init__(self, *, width: int, height: int) -> None:
        # TIME_HIGH, TIME_LOW (-1: none yet), wraps, y, base x, polarity, valid
        super().__init__(width=width, height=height, state=[-1, -1, 0, 0, 0, 0, 0])

    def decode(self, payload: np.ndarray | bytes | memoryview, *, xyp: bool = False) -> Events:
        """Decode one message's payload; the state moves on to its end."""
        return self._run(_kernels.evt3_decode, payload, xyp)


def encode_evt3(t_us: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray) -> bytes:
    """evt3 words for time-sorted events (sensor microseconds, any size: the low 24 bits are sent).

    Every payload starts with TIME_HIGH, TIME_LOW and ADDR_Y words, so it decodes on its own as well
    as in a stream; after that a time or y word is written only when its value changes, then one
    ADDR_X per event. Used by the simulator and the tests; drivers write evt3 themselves.
    """
    t_us = np.asarray(t_us, np.int64) & 0xFFFFFF
    n = t_us.size
    if n == 0:
        return b''
    high = (t_us >> 12) & 0xFFF
    low = t_us & 0xFFF
    y = np.asarray(y, np.int64) & 0x7FF
    changed = np.ones(n, bool)
    new_high = changed.copy()
    new_high[1:] = high[1:] != high[:-1]
    new_low = changed.copy()
    new_low[1:] = low[1:] != low[:-1]
    new_y = changed.copy()
    new_y[1:] = y[1:] != y[:-1]
    per_event = new_high.astype(np.int64) + new_low + new_y + 1
    end = np.cumsum(per_event)
    words = np.empty(int(end[-1]), np.uint16)
    pos = end - 1
    words[pos] = (0x2 << 12) | (np.asarray(x, np.int64) & 0x7FF) | ((np.asarray(p, np.int64) & 1) << 11)
    pos_y = pos - new_y
    words[pos_y[new_y]] = (y[new_y]).astype(np.uint16)
    pos_low = pos_y - new_low
    words[pos_low[new_low]] = ((0x6 << 12) | low[new_low]).astype(np.uint16)
    pos_high = pos_low - new_high
    words[pos_high[new_high]] = ((0x8 << 12) | high[new_high]).astype(np.uint16)
    return words.astype('<u2').tobytes()



class Evt3Retimer:
    """Rewrites one stream's evt3 time words so that sensor time u reads u + round(k (u - u0)).

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
