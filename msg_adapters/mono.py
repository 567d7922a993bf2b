"""``mono`` payloads (EventPacket encoding ``mono``, deprecated): one little-endian uint64 per event.

    bit 63 polarity, bits 48-62 y, bits 32-47 x, bits 0-31 dt (ns)
    event time (ns) = time_base + dt

No state carries between messages. dt going backwards inside a message is kept and counted;
trailing bytes that do not make a whole event are counted.
"""

from __future__ import annotations

import numpy as np

from msg_adapters import _kernels
from msg_adapters.events import Events, WordLoopDecoder, byte_view, whole_units


class MonoDecoder(WordLoopDecoder):
    """Decoder of one stream's mono payloads (no state)."""

    counter_names = ('time going backwards within a message',)

    def __init__(self, *, width: int = 0, height: int = 0) -> None:
        super().__init__(width=width, height=height, state=[])

    def decode(self, payload: np.ndarray | bytes | memoryview, *, time_base: int, xyp: bool = False) -> Events:
        buf = whole_units(byte_view(payload), 8, self.anomalies, 'trailing bytes (not a whole mono event)')
        if buf.size == 0:
            return Events.empty(xyp=xyp)
        halves = buf.view('<u4').reshape(-1, 2)
        t = halves[:, 0].astype(np.int64)
        t += int(time_base)
        self.anomalies.count(self.counter_names[0], int(np.count_nonzero(t[1:] < t[:-1])))
        if not xyp:
            return Events(t)
        high = halves[:, 1]
        return Events(t, (high & 0xFFFF).astype(np.uint16), ((high >> 16) & 0x7FFF).astype(np.uint16),
                      (high >> 31).astype(np.uint8))

    def packet_step(self, raw: bytes | bytearray | memoryview, *, grid_ns: int, counts: np.ndarray
                    ) -> tuple[tuple[int, ...], np.ndarray] | None:
        """``decode`` of a well-formed packet in one C call (``_kernels.mono_packet_step``), as
        ``LibcaerDecoder.packet_step``."""
        return self._packet_step(_kernels.mono_packet_step, raw, 8, grid_ns, counts)
