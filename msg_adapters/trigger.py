"""``trigger`` payloads (EventPacket encoding ``trigger``, deprecated): external trigger edges.

One little-endian uint64 per trigger: bit 63 edge, bits 0-31 dt (ns); time = time_base + dt.
Triggers are not contrast events: the adapter recognises the encoding and yields no events (its
``triggers`` method gives the edges for anyone who wants them).
"""

from __future__ import annotations

import numpy as np

from msg_adapters.events import Anomalies, Events, byte_view, whole_units


class TriggerDecoder:
    """Recognises trigger payloads: no contrast events."""

    def __init__(self) -> None:
        self.anomalies = Anomalies()

    def decode(self, payload: np.ndarray | bytes | memoryview, *, time_base: int, xyp: bool = False) -> Events:
        whole_units(byte_view(payload), 8, self.anomalies, 'trailing bytes (not a whole trigger)')
        return Events.empty(xyp=xyp)

    @staticmethod
    def triggers(payload: np.ndarray | bytes | memoryview, *, time_base: int) -> tuple[np.ndarray, np.ndarray]:
        """(times in ns, edges) of the whole triggers in a payload."""
        buf = byte_view(payload)
        halves = buf[: buf.size - buf.size % 8].view('<u4').reshape(-1, 2)
        return halves[:, 0].astype(np.int64) + int(time_base), (halves[:, 1] >> 31).astype(np.uint8)
