"""iniVation compressed payloads (EventPacket encoding ``libcaer_cmp``, libcaer_driver's default).

Little-endian 16-bit words, code in the top 4 bits (the layout of event_camera_codecs'
``libcaer_cmp_types.h``):

    0 TIME_HIGH    time bits 12-23 (microseconds)
    1 TIME_LOW     time bits 0-11
    2 ADDR_X       x = bits 0-10: the current x
    3 ADDR_Y       y = bits 0-10, polarity bit 11: one event at the current x and time
    4 VECT_BASE_Y  base y = bits 0-10, polarity bit 11
    5 VECT_8       8-bit mask along y: an event at (x, base_y + i) per set bit i; then base_y += 8
    6 VECT_12      defined by the format, not written by libcaer_driver: counted, not decoded

Time words are microseconds from the message's ``time_base`` and restart at zero in every message:

    event time (ns) = time_base + ((TIME_HIGH << 12) | TIME_LOW) * 1000

``time_base`` is host (ROS) time at driver start plus the sensor's elapsed time, so these are
ROS-timeline times already. The current x, base y and polarity carry from one message to the next,
as they do upstream. Events outside the sensor geometry are counted, not emitted. The word loop is
C (``msg_adapters/_kernels.c``).
"""

from __future__ import annotations

import numpy as np

from msg_adapters import _kernels
from msg_adapters.events import Events, WordLoopDecoder


class LibcaerCmpDecoder(WordLoopDecoder):
    """Stateful decoder of one stream's libcaer_cmp payloads."""

    counter_names = ('unknown word type', 'VECT_12 word (not decoded)', 'event outside the sensor geometry')
    per_word = 8

    def __init__(self, *, width: int, height: int) -> None:
        super().__init__(width=width, height=height, state=[0, 0, 0])  # current x, base y, polarity

    def decode(self, payload: np.ndarray | bytes | memoryview, *, time_base: int, xyp: bool = False) -> Events:
        """Decode one message's payload, its time words counted from ``time_base`` (ns)."""
        return self._run(_kernels.cmp_decode, payload, xyp, int(time_base))

    def packet_step(self, raw: bytes | bytearray | memoryview, *, grid_ns: int, counts: np.ndarray
                    ) -> tuple[tuple[int, ...], np.ndarray] | None:
        """``decode`` of a well-formed packet's payload from its time_base, its events counted on the
        grid of ``grid_ns`` into ``counts``, in one C call (``_kernels.cmp_packet_step``: what it
        returns, and the scratch its times are in). None for any other message, nothing moved."""
        return self._packet_step(_kernels.cmp_packet_step, raw, 2, grid_ns, counts)
