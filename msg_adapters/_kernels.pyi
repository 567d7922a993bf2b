# Types of the C word loops (_kernels.c). Each decodes one payload's 16-bit words, carrying its state
# (int64 array) from call to call and counting odd words in ``counters``; it writes at most
# ``capacity`` events into t (and x, y, p when given) and returns (events written, odd words seen); the
# ``_edges`` variants also write evt3 trigger edges (at most ``edge_capacity``) and return their number.
import numpy as np
import numpy.typing as npt

_Words = npt.NDArray[np.uint8]
_I64 = npt.NDArray[np.int64]

def evt3_decode(words: _Words, state: _I64, counters: _I64, width: int, height: int, capacity: int, t: _I64,
                x: npt.NDArray[np.uint16] | None, y: npt.NDArray[np.uint16] | None,
                p: npt.NDArray[np.uint8] | None, /) -> tuple[int, int]: ...
def evt3_packet_decode(raw: bytes | bytearray | memoryview, state: _I64, counters: _I64, width: int, height: int,
                       capacity: int, t: _I64,
                       x: npt.NDArray[np.uint16] | None, y: npt.NDArray[np.uint16] | None,
                       p: npt.NDArray[np.uint8] | None, ros1: bool = False, /) -> tuple[int, int, int, int] | None: ...
def evt3_decode_edges(words: _Words, state: _I64, counters: _I64, width: int, height: int, capacity: int, t: _I64,
                      x: npt.NDArray[np.uint16] | None, y: npt.NDArray[np.uint16] | None,
                      p: npt.NDArray[np.uint8] | None, edge_capacity: int, edge_t: _I64,
                      edge_value: npt.NDArray[np.uint8], edge_channel: npt.NDArray[np.uint16], /
                      ) -> tuple[int, int, int]: ...
def evt3_packet_decode_edges(raw: bytes | bytearray | memoryview, state: _I64, counters: _I64, width: int,
                             height: int, capacity: int, t: _I64, x: npt.NDArray[np.uint16] | None,
                             y: npt.NDArray[np.uint16] | None, p: npt.NDArray[np.uint8] | None, edge_capacity: int,
                             edge_t: _I64, edge_value: npt.NDArray[np.uint8], edge_channel: npt.NDArray[np.uint16],
                             ros1: bool, /) -> tuple[int, int, int, int, int] | None: ...
def cmp_decode(words: _Words, state: _I64, counters: _I64, width: int, height: int, time_base: int, capacity: int,
               t: _I64, x: npt.NDArray[np.uint16] | None, y: npt.NDArray[np.uint16] | None,
               p: npt.NDArray[np.uint8] | None, /) -> tuple[int, int]: ...
def evt3_first_time(payload: bytes | memoryview, state: _I64, /) -> int: ...
def evt3_first_events(payload: bytes | memoryview, state: _I64, width: int, height: int, /) -> tuple[int, int]: ...
def evt3_retime(payload: bytes | memoryview, state: _I64, mode: int, k: float, a_in: int, off: int, anchor: int,
                a_out: int, /) -> bytes | None: ...
def evt3_packet_restamp(raw: bytes | bytearray | memoryview, rstate: _I64, anchors: _I64, k: float, off: int,
                        anchor: int, ros1: bool, /) -> tuple[int, bytearray | None, bytes | None] | None: ...
def event_array_restamp(raw: bytes | bytearray | memoryview, off: int, k: float, anchor: int, identity: bool,
                        ros1: bool, /) -> bytearray | None: ...
def evt3_packets_restamp(chunk: bytes | memoryview, rows: _I64, start: int, rstate: _I64, anchors: _I64, k: float,
                         off: int, anchor: int, stamps: _I64, new: list[bytes | bytearray | None], ros1: bool, /
                         ) -> int: ...
def event_arrays_restamp(chunk: bytes | memoryview, rows: _I64, start: int, off: int, k: float, anchor: int,
                         identity: bool, new: list[bytes | bytearray | None], ros1: bool, /) -> int: ...
def event_array_times(raw: bytes | bytearray | memoryview, ros1: bool, /) -> tuple[bytearray, int, int] | None: ...
def evt3_packet_step(raw: bytes | bytearray | memoryview, state: _I64, counters: _I64, width: int, height: int,
                     capacity: int, t: _I64, anchor: int, has_anchor: bool, grid: int, counts: npt.NDArray[np.int32],
                     restamp: bool, rstate: _I64, anchors: _I64, k: float, off: int, canchor: int,
                     edge_capacity: int, edges: tuple[_I64, npt.NDArray[np.uint8], npt.NDArray[np.uint16]] | None, /
                     ) -> tuple[int, int, int, int, int, int, int, int, int, bytes | None,
                                tuple[int, bytearray | None, bytes | None] | None, int] | None: ...
def cmp_packet_step(raw: bytes | bytearray | memoryview, state: _I64, counters: _I64, width: int, height: int,
                    capacity: int, t: _I64, grid: int, counts: npt.NDArray[np.int32], /
                    ) -> tuple[int, int, int, int, int, int, int, int, int, int] | None: ...
def event_array_step(raw: bytes | bytearray | memoryview, grid: int, counts: npt.NDArray[np.int32], restamp: bool,
                     off: int, k: float, anchor: int, identity: bool, /
                     ) -> tuple[bytearray, int, int, int, int, int, int, int, bytearray | None] | None: ...
def message_key(raw: bytes | bytearray | memoryview, edge: int, /) -> tuple[int, int | None]: ...
