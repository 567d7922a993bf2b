"""Prophesee EVT 3.0 payloads (EventPacket encoding ``evt3``), decoded with numpy, statefully.

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
before by more than 10 counts as a wrap (smaller backward steps happen without one); wraps are
counted in the decoder state, so times stay monotonic across messages. Events before the
stream's first TIME_HIGH-then-TIME_LOW pair have no valid time and are dropped, as are events
outside the sensor geometry, as event_camera_codecs does. The whole state (time high and low,
wrap count, y, base x, polarity) carries from one message to the next.

Times are *sensor* time: metavision_driver sets time_base = 0 and the payload alone holds time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

ADDR_Y, ADDR_X, VECT_BASE_X, VECT_12, VECT_8, TIME_LOW, TIME_HIGH = 0x0, 0x2, 0x3, 0x4, 0x5, 0x6, 0x8
KNOWN_TYPES = frozenset({ADDR_Y, ADDR_X, VECT_BASE_X, VECT_12, VECT_8, TIME_LOW, 0x7, TIME_HIGH, 0x9, 0xA, 0xE, 0xF})
_IS_KNOWN = np.isin(np.arange(16), sorted(KNOWN_TYPES))  # word type -> known
_WRAP_US = 1 << 24
_MIN_WRAP_STEP = 10
_BITS = np.arange(12, dtype=np.uint16)


@dataclass
class Evt3State:
    """What carries from one message to the next."""

    time_high: int = -1
    """Last TIME_HIGH value (12 bits); -1 before the first."""
    time_low: int = -1
    """Last TIME_LOW value; -1 before the first valid time."""
    wraps: int = 0
    y: int = 0
    base_x: int = 0
    polarity: int = 0
    valid: bool = False
    """True once a TIME_HIGH then a TIME_LOW have been seen."""
    anomalies: dict[str, int] = field(default_factory=dict)

    def count(self, what: str, n: int = 1) -> None:
        if n:
            self.anomalies[what] = self.anomalies.get(what, 0) + int(n)


@dataclass(frozen=True)
class Events:
    """Decoded events: times in ns (sensor time), and x, y, polarity when asked for."""

    t: np.ndarray
    x: np.ndarray | None = None
    y: np.ndarray | None = None
    p: np.ndarray | None = None


def _ffill(mask: np.ndarray, values: np.ndarray, initial: int, index: np.ndarray) -> np.ndarray:
    """For every word, the value at the last word where ``mask`` holds (``initial`` before any).

    ``index`` is ``np.arange(mask.size)``, made once per message by the caller.
    """
    idx = np.where(mask, index, -1)
    np.maximum.accumulate(idx, out=idx)
    out = values[np.maximum(idx, 0)].astype(np.int64)
    out[idx < 0] = initial
    return out


class Evt3Decoder:
    """Stateful decoder of one stream's evt3 payloads."""

    def __init__(self, *, width: int, height: int) -> None:
        self.width = width
        self.height = height
        self.state = Evt3State()

    def decode(self, payload: np.ndarray | bytes, *, xyp: bool = False) -> Events:
        """Decode one message's payload; the state moves on to its end."""
        buf = np.frombuffer(payload, dtype=np.uint8) if isinstance(payload, (bytes, bytearray)) else payload
        st = self.state
        if buf.size % 2:
            st.count('odd byte count')
            buf = buf[: buf.size - 1]
        words = buf.view('<u2')
        n = words.size
        if n == 0:
            if not xyp:
                return Events(np.empty(0, np.int64))
            return Events(np.empty(0, np.int64), np.empty(0, np.uint16), np.empty(0, np.uint16), np.empty(0, np.uint8))
        typ = words >> 12
        val = words & 0x0FFF
        st.count('unknown word type', int(n - np.count_nonzero(_IS_KNOWN[typ])))
        index = np.arange(n)

        # --- time at every word: rollover count, TIME_HIGH and TIME_LOW carried forward.
        is_th = typ == TIME_HIGH
        is_tl = typ == TIME_LOW
        th_vals = val[is_th].astype(np.int64)
        if th_vals.size:
            prev = np.empty_like(th_vals)
            prev[0] = st.time_high if st.time_high >= 0 else th_vals[0]
            prev[1:] = th_vals[:-1]
            step_back = prev - th_vals
            wrapped = step_back > _MIN_WRAP_STEP
            st.count('small backward time step', int(np.count_nonzero((step_back > 0) & ~wrapped)))
            high_full = (st.wraps + np.cumsum(wrapped)) * _WRAP_US + (th_vals << 12)
        else:
            high_full = th_vals
        high_all = np.zeros(n, np.int64)
        high_all[is_th] = high_full
        initial_high = st.wraps * _WRAP_US + (max(st.time_high, 0) << 12)
        high = _ffill(is_th, high_all, initial_high, index)
        low = _ffill(is_tl, val, max(st.time_low, 0), index)
        t_us = high | low

        # --- validity: nothing before the stream's first TIME_HIGH followed by a TIME_LOW.
        first_valid = 0
        became_valid = False
        if not st.valid:
            th_pos = np.flatnonzero(is_th)
            tl_after = np.flatnonzero(is_tl & (index > th_pos[0])) if th_pos.size else th_pos
            became_valid = tl_after.size > 0
            first_valid = int(tl_after[0]) + 1 if became_valid else n

        # --- events per word: ADDR_X one, vectors one per set mask bit.
        is_x = typ == ADDR_X
        is_v12 = typ == VECT_12
        is_v8 = typ == VECT_8
        ev_word = is_x | is_v12 | is_v8
        ev_word[:first_valid] = False
        mask = np.where(is_v12, val, np.where(is_v8, val & 0xFF, 1)).astype(np.uint16)

        is_y = typ == ADDR_Y
        y = _ffill(is_y, val & 0x7FF, st.y, index)
        is_base = typ == VECT_BASE_X
        vec_inc = np.where(is_v12, 12, np.where(is_v8, 8, 0)).astype(np.int64)
        inc_before = np.cumsum(vec_inc) - vec_inc  # increments of the vectors before each word
        base_anchor = np.where(is_base, (val & 0x7FF).astype(np.int64) - inc_before, 0)
        base_x = _ffill(is_base, base_anchor, st.base_x, index) + inc_before
        pol_vec = _ffill(is_base, (val >> 11) & 1, st.polarity, index)

        rows_w = np.flatnonzero(ev_word)
        bits = (mask[rows_w, None] >> _BITS) & 1
        bits[is_x[rows_w], 1:] = 0
        r, c = np.nonzero(bits)
        w = rows_w[r]
        ex = np.where(is_x[w], val[w] & 0x7FF, base_x[w] + c)
        ey = y[w]
        inside = (ex < self.width) & (ey < self.height)
        st.count('event outside the sensor geometry', int(ex.size - np.count_nonzero(inside)))
        w = w[inside]
        t_ns = t_us[w] * 1000

        # --- state at the end of the message.
        if th_vals.size:
            st.wraps = int(high_full[-1] // _WRAP_US)
            st.time_high = int(th_vals[-1])
        if np.any(is_tl):
            st.time_low = int(val[is_tl][-1])
        st.valid = st.valid or became_valid
        st.y = int(y[-1])
        st.base_x = int(base_x[-1] + vec_inc[-1])
        st.polarity = int(pol_vec[-1])
        if not xyp:
            return Events(t_ns)
        ex = ex[inside].astype(np.uint16)
        ey = ey[inside].astype(np.uint16)
        ep = np.where(is_x[w], (val[w] >> 11) & 1, pol_vec[w]).astype(np.uint8)
        return Events(t_ns, ex, ey, ep)

