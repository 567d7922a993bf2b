"""event_camera_msgs/EventPacket straight from CDR bytes: fields and byte offsets, no objects.

CDR (XCDR1, little endian): a 4-byte encapsulation header, then the fields, each aligned to its
own size counted from the end of the encapsulation header:

    header.stamp.sec int32, header.stamp.nanosec uint32, header.frame_id string,
    height uint32, width uint32, seq uint64, time_base uint64, encoding string,
    is_bigendian bool, events uint8[] (uint32 length, then the bytes)
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from evsync_ros.errors import MessageError

_CDR_LE = (b'\x00\x01', b'\x00\x03')  # CDR_LE, PL_CDR_LE representation identifiers
#: header.stamp (int32 sec, uint32 nanosec) always starts right after the encapsulation header.
STAMP_OFFSET = 4


def _align(pos: int, size: int) -> int:
    rel = pos - 4
    return pos + (-rel % size)


def _read_string(raw: bytes | memoryview, pos: int, what: str) -> tuple[str, int]:
    pos = _align(pos, 4)
    if pos + 4 > len(raw):
        raise MessageError(f'EventPacket truncated before {what}')
    (length,) = struct.unpack_from('<I', raw, pos)
    pos += 4
    if length == 0 or pos + length > len(raw):
        raise MessageError(f'EventPacket {what} has an impossible length {length}')
    text = bytes(raw[pos : pos + length - 1]).decode('utf-8', errors='replace')
    return text, pos + length


@dataclass(frozen=True)
class PacketView:
    """An EventPacket's fields, and where the time fields sit in the serialized bytes."""

    stamp_ns: int
    frame_id: str
    height: int
    width: int
    seq: int
    time_base: int
    encoding: str
    is_bigendian: bool
    events: np.ndarray
    """The payload as a read-only uint8 view into the message bytes."""
    time_base_offset: int
    """Where the uint64 time_base sits in the serialized bytes (it follows a variable-length frame_id)."""


def parse_event_packet(raw: bytes | bytearray | memoryview) -> PacketView:
    """Read an EventPacket's CDR bytes; MessageError when they do not hold one."""
    if len(raw) < 4 or bytes(raw[:2]) not in _CDR_LE:
        raise MessageError('EventPacket is not little-endian CDR (bad or missing encapsulation header)')
    if len(raw) < 16:
        raise MessageError(f'EventPacket truncated: {len(raw)} bytes')
    sec, nanosec = struct.unpack_from('<iI', raw, STAMP_OFFSET)
    frame_id, pos = _read_string(raw, 12, 'header.frame_id')
    pos = _align(pos, 4)
    if pos + 8 > len(raw):
        raise MessageError('EventPacket truncated before height/width')
    height, width = struct.unpack_from('<II', raw, pos)
    pos = _align(pos + 8, 8)
    if pos + 16 > len(raw):
        raise MessageError('EventPacket truncated before seq/time_base')
    seq, time_base = struct.unpack_from('<QQ', raw, pos)
    time_base_offset = pos + 8
    encoding, pos = _read_string(raw, pos + 16, 'encoding')
    if pos + 1 > len(raw):
        raise MessageError('EventPacket truncated before is_bigendian')
    is_bigendian = raw[pos] != 0
    pos = _align(pos + 1, 4)
    if pos + 4 > len(raw):
        raise MessageError('EventPacket truncated before the events length')
    (n_bytes,) = struct.unpack_from('<I', raw, pos)
    pos += 4
    if pos + n_bytes > len(raw):
        raise MessageError(f'EventPacket truncated: events declares {n_bytes} bytes, {len(raw) - pos} present')
    events = np.frombuffer(raw, dtype=np.uint8, count=n_bytes, offset=pos)
    return PacketView(
        stamp_ns=sec * 1_000_000_000 + nanosec,
        frame_id=frame_id,
        height=height,
        width=width,
        seq=seq,
        time_base=time_base,
        encoding=encoding,
        is_bigendian=is_bigendian,
        events=events,
        time_base_offset=time_base_offset,
    )
