"""libcaer polarity events (EventPacket encoding ``libcaer``): 8 bytes per event, little endian.

    uint32 data       polarity bit 1, y bits 2-16, x bits 17-31
    int32  timestamp  microseconds, 31 bits (it overflows from 2^31 - 1 to 0)

    event time (ns) = time_base + timestamp * 1000 + overflows * 2^31 * 1000

``time_base`` is host (ROS) time at driver start plus the high bits of the sensor's elapsed time,
so an overflow inside a message shows as a timestamp smaller than the one before by more than
2^30 us; the decoder adds 2^31 us from there to the message's end, as event_camera_codecs does.
Across messages, the driver folds each overflow into ``time_base``; should a message nevertheless
start more than 2^30 us before the stream's last time, the decoder carries one overflow for the
rest of the stream and counts it. Smaller backward steps are kept as they are and counted, as are
negative timestamps (bit 31 set: not a libcaer time; the low 31 bits are used) and trailing bytes
that do not make a whole event.
"""

from __future__ import annotations

import numpy as np

from msg_adapters import _kernels
from msg_adapters.events import Events, WordLoopDecoder, byte_view, whole_units

_OVERFLOW_NS = (1 << 31) * 1000
_HALF_NS = (1 << 30) * 1000


class LibcaerDecoder(WordLoopDecoder):
    """Decoder of one stream's libcaer payloads; it keeps the stream's overflow carry, in the state its
    one C call (``packet_step``) shares: the carry (ns), whether a time has come, the last time."""

    counter_names = ('negative libcaer timestamp', 'time going backwards within a message',
                     '31-bit overflow missing from time_base (carried)')

    def __init__(self, *, width: int = 0, height: int = 0) -> None:
        super().__init__(width=width, height=height, state=[0, 0, 0])

    def decode(self, payload: np.ndarray | bytes | memoryview, *, time_base: int, xyp: bool = False) -> Events:
        """Decode one message's payload; ``time_base`` (ns) from the message."""
        buf = whole_units(byte_view(payload), 8, self.anomalies, 'trailing bytes (not a whole libcaer event)')
        if buf.size == 0:
            return Events.empty(xyp=xyp)
        pairs = buf.view('<u4').reshape(-1, 2)
        ts = pairs[:, 1].astype(np.int64)
        negative = ts >= 1 << 31
        if negative.any():
            self.anomalies.count(self.counter_names[0], int(np.count_nonzero(negative)))
            ts &= (1 << 31) - 1
        t = ts * 1000
        step = np.diff(t)
        over = step < -_HALF_NS
        if over.any():
            t[1:] += np.cumsum(over) * _OVERFLOW_NS
        self.anomalies.count(self.counter_names[1], int(np.count_nonzero((step < 0) & ~over)))
        carry, has_last, last = (int(v) for v in self._state)
        t += int(time_base) + carry
        if has_last and int(t[0]) < last - _HALF_NS:
            self.anomalies.count(self.counter_names[2])
            self._state[0] = carry + _OVERFLOW_NS
            t += _OVERFLOW_NS
        self._state[1:] = (1, int(t[-1]))
        if not xyp:
            return Events(t)
        data = pairs[:, 0]
        return Events(t, ((data >> 17) & 0x7FFF).astype(np.uint16), ((data >> 2) & 0x7FFF).astype(np.uint16),
                      ((data >> 1) & 1).astype(np.uint8))

    def packet_step(self, raw: bytes | bytearray | memoryview, *, grid_ns: int, counts: np.ndarray
                    ) -> tuple[tuple[int, ...], np.ndarray] | None:
        """``decode`` of a well-formed packet of the stream's geometry and whole events, its events
        counted on the grid of ``grid_ns`` into ``counts``, in one C call (``_kernels.libcaer_packet_step``,
        as ``LibcaerCmpDecoder.packet_step``). None for any other message, nothing moved."""
        return self._packet_step(_kernels.libcaer_packet_step, raw, 8, grid_ns, counts)
