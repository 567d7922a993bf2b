"""``trigger`` payloads (EventPacket encoding ``trigger``, deprecated): external trigger edges.

One little-endian uint64 per edge (event_camera_codecs' ``trigger_decoder.h``):

    bit 63 edge value (1 rising), bits 48-62 channel id, bits 0-31 dt (ns)
    edge time (ns) = time_base + dt

No state carries between messages. Triggers are not contrast events: ``decode`` yields none;
``decode_edges`` gives the edges. dt going backwards inside a message is kept and counted, and
trailing bytes that do not make a whole edge are counted.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from msg_adapters.edges import TriggerEdges
from msg_adapters.events import Anomalies, Events, byte_view, whole_units


class TriggerDecoder:
    """Decoder of one stream's trigger payloads: edges, no contrast events."""

    def __init__(self) -> None:
        self.anomalies = Anomalies()

    def decode(self, payload: np.ndarray | bytes | memoryview, *, time_base: int, xyp: bool = False) -> Events:
        """No events (the payload's trailing bytes counted)."""
        return self.decode_edges(payload, time_base=time_base, xyp=xyp)[0]

    def decode_edges(self, payload: np.ndarray | bytes | memoryview, *, time_base: int, xyp: bool = False
                     ) -> tuple[Events, TriggerEdges]:
        """(no events, the payload's edges), each time ``time_base`` + dt (ns)."""
        buf = whole_units(byte_view(payload), 8, self.anomalies, 'trailing bytes (not a whole trigger)')
        if buf.size == 0:
            return Events.empty(xyp=xyp), TriggerEdges.empty()
        halves = buf.view('<u4').reshape(-1, 2)
        t = halves[:, 0].astype(np.int64)
        self.anomalies.count('time going backwards within a message', int(np.count_nonzero(t[1:] < t[:-1])))
        t += int(time_base)
        high = halves[:, 1]
        return Events.empty(xyp=xyp), TriggerEdges(t, (high >> 31).astype(np.uint8),
                                                   ((high >> 16) & 0x7FFF).astype(np.uint16))


def encode_trigger(dt_ns: npt.ArrayLike, value: npt.ArrayLike, channel: npt.ArrayLike) -> bytes:
    """A ``trigger`` payload of edges at ``dt_ns`` (0 to 2^32 - 1) after the message's time_base, with
    their values (0/1) and channel ids (0 to 2^15 - 1). Used by the simulator and the tests."""
    dt = np.asarray(dt_ns, np.int64)
    if dt.size and (dt.min() < 0 or dt.max() >= 1 << 32):
        raise ValueError('trigger dt must lie within 0 to 2^32 - 1 ns of the time base')
    words = (dt.astype(np.uint64) | (np.asarray(channel, np.uint64) & 0x7FFF) << np.uint64(48)
             | (np.asarray(value, np.uint64) & 1) << np.uint64(63))
    return words.astype('<u8').tobytes()
