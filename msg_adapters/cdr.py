"""The few CDR facts every adapter shares (XCDR1, little endian, as ROS 2 serialises).

A serialized message starts with a 4-byte encapsulation header; every field is then aligned to
its own size counted from the end of that header. Every event message starts with a
std_msgs/Header, so header.stamp (int32 sec, uint32 nanosec) always sits at bytes 4-12 and
header.frame_id (uint32 length with its NUL, then the bytes) starts at byte 12.
"""

from __future__ import annotations

import struct

from msg_adapters.errors import MessageError

_CDR_LE = (b'\x00\x01', b'\x00\x03')  # CDR_LE, PL_CDR_LE representation identifiers
NS = 1_000_000_000
STAMP_OFFSET = 4
FRAME_ID_OFFSET = 12
INT32_MIN, INT32_MAX = -(1 << 31), (1 << 31) - 1
MAX_TIME_NS = (INT32_MAX + 1) * NS - 1
"""The latest time builtin_interfaces/Time holds: no time field of a ROS message means more."""


def align(pos: int, size: int) -> int:
    """``pos`` moved up to the next multiple of ``size`` counted from the encapsulation header's end."""
    return pos + (-(pos - 4) % size)


def check_encapsulation(raw: bytes | bytearray | memoryview, what: str) -> None:
    """MessageError naming ``what`` unless ``raw`` starts with a little-endian CDR header and holds a header.stamp."""
    if len(raw) < 4 or bytes(raw[:2]) not in _CDR_LE:
        raise MessageError(f'{what} is not little-endian CDR (bad or missing encapsulation header)')
    if len(raw) < 16:
        raise MessageError(f'{what} truncated: {len(raw)} bytes')


def read_stamp(raw: bytes | bytearray | memoryview) -> int:
    """header.stamp (int ns) of any serialized message that begins with a std_msgs/Header."""
    sec, nanosec = struct.unpack_from('<iI', raw, STAMP_OFFSET)
    return int(sec) * NS + int(nanosec)


def write_stamp(out: bytearray, stamp_ns: int, what: str) -> None:
    """Write header.stamp in place; MessageError if builtin_interfaces/Time cannot hold it."""
    sec, nsec = divmod(int(stamp_ns), NS)
    if not INT32_MIN <= sec <= INT32_MAX:
        raise MessageError(f'{what}: header.stamp {stamp_ns} ns is outside what builtin_interfaces/Time holds')
    struct.pack_into('<iI', out, STAMP_OFFSET, sec, nsec)


def read_string(raw: bytes | bytearray | memoryview, pos: int, field: str, what: str) -> tuple[str, int]:
    """(text, position after it) of the CDR string at ``pos``; MessageError when it cannot be one."""
    pos = align(pos, 4)
    if pos + 4 > len(raw):
        raise MessageError(f'{what} truncated before {field}')
    (length,) = struct.unpack_from('<I', raw, pos)
    pos += 4
    if length == 0 or pos + length > len(raw):
        raise MessageError(f'{what} {field} has an impossible length {length}')
    text = bytes(raw[pos : pos + length - 1]).decode('utf-8', errors='replace')
    return text, pos + length
