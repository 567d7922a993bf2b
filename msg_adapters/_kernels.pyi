# Types of the C word loops (_kernels.c). Each decodes one payload's 16-bit words, carrying its state
# (int64 array) from call to call and counting odd words in ``counters``; it writes at most
# ``capacity`` events into t (and x, y, p when given) and returns (events written, odd words seen).
import numpy as np
import numpy.typing as npt

_Words = npt.NDArray[np.uint8]
_I64 = npt.NDArray[np.int64]

def evt3_decode(words: _Words, state: _I64, counters: _I64, width: int, height: int, capacity: int, t: _I64,
                x: npt.NDArray[np.uint16] | None, y: npt.NDArray[np.uint16] | None,
                p: npt.NDArray[np.uint8] | None, /) -> tuple[int, int]: ...
def cmp_decode(words: _Words, state: _I64, counters: _I64, width: int, height: int, time_base: int, capacity: int,
               t: _I64, x: npt.NDArray[np.uint16] | None, y: npt.NDArray[np.uint16] | None,
               p: npt.NDArray[np.uint8] | None, /) -> tuple[int, int]: ...
def evt3_first_time(payload: bytes | memoryview, state: _I64, /) -> int: ...
def evt3_first_events(payload: bytes | memoryview, state: _I64, width: int, height: int, /) -> tuple[int, int]: ...
def evt3_retime(payload: bytes | memoryview, state: _I64, mode: int, k: float, a_in: int, off: int, anchor: int,
                a_out: int, /) -> bytes | None: ...
