# Types of the C walk over an mcap chunk's Message records (_mcap.c).
import numpy as np
import numpy.typing as npt

def message_records(chunk: bytes | memoryview, /) -> bytes: ...
def build_chunk(src: bytes | memoryview, rows: npt.NDArray[np.int64], logs: npt.NDArray[np.int64],
                stamps: npt.NDArray[np.int64], new: list[bytes | bytearray | None], out: bytearray, /
                ) -> tuple[int, bytes]: ...
