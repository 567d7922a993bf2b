"""Any message that begins with a ``std_msgs/Header`` (Imu, Image, CompressedImage, CameraInfo, a
trigger packet, ...): a camera's companion topics, restamped with that camera's correction.

Only ``header.stamp`` moves; every other byte of the message is kept. The header's frame_id follows
the stamp in CDR, so the stamp is always the eight bytes after the encapsulation header.
"""

from __future__ import annotations

import struct

from msg_adapters.cdr import STAMP_OFFSET, check_encapsulation, read_stamp, write_stamp
from msg_adapters.errors import MessageError
from msg_adapters.protocols import Correction


def restamp_header(raw: bytes | bytearray | memoryview, correction: Correction, *, what: str = 'message') -> bytes:
    """``raw`` (CDR, beginning with a std_msgs/Header) with ``header.stamp`` moved by ``correction``;
    MessageError naming ``what`` when it cannot be such a message."""
    check_encapsulation(raw, what)  # also: long enough for the stamp and frame_id's length
    (nanosec,) = struct.unpack_from('<I', raw, STAMP_OFFSET + 4)
    if nanosec >= 1_000_000_000:
        raise MessageError(f'{what}: header.stamp.nanosec {nanosec} is not below one second')
    out = bytearray(raw)
    write_stamp(out, correction.apply_one(read_stamp(raw)), what)
    return bytes(out)
