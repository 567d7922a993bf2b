"""Any message that begins with a ``std_msgs/Header`` (Imu, Image, CompressedImage, CameraInfo, a
trigger packet, ...): a camera's companion topics, restamped with that camera's correction.

Only ``header.stamp`` moves; every other byte of the message is kept. The header's frame_id follows
the stamp in CDR, so the stamp is always the eight bytes after the encapsulation header.
"""

from __future__ import annotations

import struct

from msg_adapters import _kernels
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


DUPLICATE_BYTES = 512
"""A message is known by its length, header.stamp, and its first and last this many bytes (which hold
an event message's first and last events' times): two different event messages never share all of them."""


def message_key(raw: bytes | bytearray | memoryview) -> tuple[int, int | None]:
    """What tells ``raw`` from every other message but a second delivery of it (a 64-bit key of its
    length, header.stamp and first and last ``DUPLICATE_BYTES``), and its header.stamp in ns (None
    for fewer than 12 bytes), in one C call."""
    return _kernels.message_key(raw, DUPLICATE_BYTES)
