"""Bags made byte by byte, with what rosbags' writers never write but files can hold: an mcap file
whose chunk index leaves out the message indexes or gives another time span than its messages',
log times past int64, a message-less chunk's inverted span, damaged compressed chunks; a ROS 1
bag whose message record headers are odd (a longer op field, a field without '='). The chunk path
of restamp must read each as the message path does (``chunkcopies``)."""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable, Iterator, Sequence
from io import BytesIO
from pathlib import Path
from typing import Any

import lz4.frame  # type: ignore[import-untyped]
import numpy as np
from rosbags.interfaces import Connection
from rosbags.rosbag2.storage_mcap import Channel, Schema, write_channel, write_schema

from evsync_ros.bag.writer import BagWriter
from msg_adapters.event_array import encode_event_array

__all__ = ['MCAP_CASES', 'PASSED_OVER', 'STRING', 'edit_mcap_channel', 'edit_ros1_messages', 'mcap', 'mcap_case',
           'two_topics', 'without_channel_counts']

STRING = b'\x00\x01\x00\x00' + (3).to_bytes(4, 'little') + b'hi\x00'
"""A std_msgs/String in CDR."""

_T = 1_700_000_000_000_000_000


def _array(t: int) -> bytes:
    one = np.array([1])
    return encode_event_array(stamp_ns=t, frame_id='f', width=10, height=10, t=np.array([t]), x=one, y=one, p=one)


MCAP_CASES: dict[str, tuple[list[tuple[int, str]], list[list[tuple[int, int, bytes]]], dict[str, Any], bool]] = {
    # name: (channels, chunks, mcap() options and 'damage', whether the chunk readers take it)
    'log time past int64 (mcap times are unsigned)': ([(1, '/s')], [[(1, 10, STRING), (1, 20, STRING),
                                                                       (1, 2**63 + 5, STRING)]], {}, False),
    'no message indexes: rosbags skips the chunk': ([(1, '/s')], [[(1, 10, STRING), (1, 20, STRING)],
                                                                  [(1, 30, STRING)]], {'message_index': False}, True),
    'a message past its chunk index span: rosbags drops it': (
        [(1, '/s')], [[(1, 10, STRING), (1, 20, STRING), (1, 30, STRING)], [(1, 40, STRING)]],
        {'spans': [(10, 20), None]}, True),
    'overlapping chunks around an inverted span': (
        [(1, '/events')], [[(1, _T, _array(_T)), (1, _T + 100, _array(_T + 100))], [(1, _T + 1, STRING)],
                           [(1, _T + 50, b'\x00\x01\x00\x00garbage')]],
        {'spans': [None, (2**63 - 1, 0), None], 'msgtype': 'dvs_msgs/msg/EventArray'}, False),
    'a damaged zstd chunk': ([(1, '/s')], [[(1, 10, STRING)] * 50], {'compression': 'zstd', 'damage': True}, True),
    'a damaged lz4 chunk': ([(1, '/s')], [[(1, 10, STRING)] * 50], {'compression': 'lz4', 'damage': True}, True),
    'lz4 chunks': ([(1, '/s'), (2, '/t')], [[(1, 10, STRING), (2, 10, STRING)], [(2, 20, STRING), (1, 21, STRING)]],
                   {'compression': 'lz4'}, True),
}
"""mcap files of ``mcap``'s making, by what they hold."""

PASSED_OVER = {'a message past its chunk index span: rosbags drops it', 'overlapping chunks around an inverted span'}
"""The cases whose file lists messages that the readers pass over (a time outside its chunk's span):
read as rosbags reads them, and refused by a whole read (``BagReader.check_whole``), the restamp's."""


def mcap_case(bag: Path, name: str) -> tuple[bool, bool]:
    """``MCAP_CASES[name]`` written as the bag ``bag`` (a folder, its file ``in.mcap``, damaged where
    the case says): (whether the chunk readers take it, whether it is damaged)."""
    channels, chunks, options, chunked = MCAP_CASES[name]
    options = dict(options)
    damage = bool(options.pop('damage', False))
    path = mcap(bag / 'in.mcap', channels, chunks, **options)
    if damage:
        data = bytearray(path.read_bytes())
        data[200:260] = bytes(b ^ 0xFF for b in data[200:260])
        path.write_bytes(bytes(data))
    return chunked, damage


def _s(x: bytes | str) -> bytes:
    x = x.encode() if isinstance(x, str) else x
    return struct.pack('<I', len(x)) + x


def _rec(op: int, body: bytes) -> bytes:
    return bytes([op]) + struct.pack('<Q', len(body)) + body


def _compress(raw: bytes, compression: str) -> bytes:
    if compression == 'zstd':
        from rosbags.rosbag2.storage_mcap import zstd  # type: ignore[attr-defined]  # rosbags' own
        return bytes(zstd.compress(raw))
    return bytes(lz4.frame.compress(raw)) if compression == 'lz4' else raw


def mcap(path: Path, channels: Sequence[tuple[int, str]], chunks: Sequence[Sequence[tuple[int, int, bytes]]], *,
         msgtype: str = 'std_msgs/msg/String', message_index: bool = True,
         spans: Sequence[tuple[int, int] | None] | None = None, compression: str = '') -> Path:
    """An mcap file (ros2 profile) at ``path``: ``channels`` (id, topic) of ``msgtype``, and ``chunks``
    of (channel, log time, data); ``message_index`` False leaves each chunk's message indexes out;
    ``spans``: per chunk, the (start, end) its index gives instead of its messages' own."""
    out = BytesIO()
    out.write(b'\x89MCAP0\r\n')
    out.write(_rec(0x01, _s('ros2') + _s('crafted')))
    schema = Schema(1, msgtype, 'ros2msg', '')
    head = BytesIO()
    write_schema(head, schema)
    for cid, topic in channels:
        write_channel(head, Channel(cid, msgtype, topic, 'cdr', _s('offered_qos_profiles') + _s('')), [schema])
    out.write(head.getvalue())
    index = []
    for n, msgs in enumerate(chunks):
        body, entries = BytesIO(), {}  # type: ignore[var-annotated]
        for cid, t, data in msgs:
            entries.setdefault(cid, []).append((t, body.tell()))
            body.write(_rec(0x05, struct.pack('<HIQQ', cid, 0, t, t) + data))
        raw = body.getvalue()
        packed = _compress(raw, compression)
        start, end = (min(t for _, t, _ in msgs), max(t for _, t, _ in msgs)) if msgs else (0, 0)
        at = out.tell()
        out.write(_rec(0x06, struct.pack('<QQQI', start, end, len(raw), zlib.crc32(raw)) + _s(compression)
                       + struct.pack('<Q', len(packed)) + packed))
        after = out.tell()
        offsets = {}
        for cid, items in entries.items() if message_index else ():
            offsets[cid] = out.tell()
            ent = b''.join(struct.pack('<QQ', t, o) for t, o in items)
            out.write(_rec(0x07, struct.pack('<HI', cid, len(ent)) + ent))
        if spans is not None and spans[n] is not None:
            start, end = spans[n]
        m = b''.join(struct.pack('<HQ', c, o) for c, o in offsets.items())
        indexes = struct.pack('<Q', out.tell() - after)
        index.append(struct.pack('<QQQQI', start, end, at, after - at, len(m)) + m + indexes + _s(compression)
                     + struct.pack('<QQ', len(packed), len(raw)))
    out.write(_rec(0x0F, struct.pack('<I', 0)))
    summary = out.tell()
    out.write(head.getvalue())
    for entry in index:
        out.write(_rec(0x08, entry))
    out.write(_rec(0x02, struct.pack('<QQI', summary, 0, 0)))
    out.write(b'\x89MCAP0\r\n')
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(out.getvalue())
    return path


def _records(buf: bytes) -> Iterator[tuple[bytes, bytes]]:
    pos = 0
    while pos < len(buf):
        (hlen,) = struct.unpack_from('<I', buf, pos)
        (dlen,) = struct.unpack_from('<I', buf, pos + 4 + hlen)
        yield buf[pos + 4:pos + 4 + hlen], buf[pos + 8 + hlen:pos + 8 + hlen + dlen]
        pos += 8 + hlen + dlen


def _fields(header: bytes) -> list[bytes]:
    pos, out = 0, []
    while pos < len(header):
        (n,) = struct.unpack_from('<I', header, pos)
        out.append(header[pos + 4:pos + 4 + n])
        pos += 4 + n
    return out


def _pack(fields: list[bytes]) -> bytes:
    return b''.join(struct.pack('<I', len(f)) + f for f in fields)


def _record(header: bytes, data: bytes) -> bytes:
    return struct.pack('<I', len(header)) + header + struct.pack('<I', len(data)) + data


def edit_ros1_messages(src: Path, dst: Path, edit: Callable[[list[bytes]], list[bytes]], *, which: int = 2) -> Path:
    """``src`` (a ROS 1 bag, uncompressed chunks) with the header fields of the ``which``-th message
    record of each chunk replaced by ``edit`` of them, the chunks' sizes and the index position
    moved to match."""
    raw = src.read_bytes()
    start = raw.index(b'\n') + 1
    recs = list(_records(raw[start:]))
    (bag_header, bag_data), body = recs[0], bytearray()
    for header, data in recs[1:]:
        fields = _fields(header)
        if b'op=\x05' in fields:  # a chunk
            inner, n = bytearray(), 0
            for mh, md in _records(data):
                mf = _fields(mh)
                if b'op=\x02' in mf:
                    n += 1
                    mf = edit(mf) if n == which else mf
                inner += _record(_pack(mf), md)
            fields = [b'size=' + struct.pack('<I', len(inner)) if f.startswith(b'size=') else f for f in fields]
            data = bytes(inner)
        body += _record(_pack(fields), data)
    old = len(raw) - start - len(_record(bag_header, bag_data))
    fields = [b'index_pos=' + struct.pack('<Q', struct.unpack('<Q', f[10:])[0] + len(body) - old)
              if f.startswith(b'index_pos=') else f for f in _fields(bag_header)]
    dst.write_bytes(raw[:start] + _record(_pack(fields), bag_data) + bytes(body))
    return dst


def edit_mcap_channel(src: Path, dst: Path, *, channel: int, which: int = 2) -> Path:
    """``src`` (an mcap file of uncompressed chunks, as rosbags writes them) with the channel id of the
    ``which``-th message record of its first chunk set to ``channel``, the chunk's checksum made to
    match (its index and statistics left as they were)."""
    data = bytearray(src.read_bytes())
    pos = 8
    while data[pos] != 0x06:  # the records before the first chunk: header, schemas, channels
        pos += 9 + struct.unpack_from('<Q', data, pos + 1)[0]
    body = pos + 9
    (clen,) = struct.unpack_from('<I', data, body + 28)
    assert not clen, 'an uncompressed chunk'
    (rlen,) = struct.unpack_from('<Q', data, body + 32)
    first = at = body + 40
    n = 0
    while at < first + rlen:
        if data[at] == 0x05:
            n += 1
            if n == which:
                struct.pack_into('<H', data, at + 9, channel)
                break
        at += 9 + struct.unpack_from('<Q', data, at + 1)[0]
    assert n == which, f'{src}: fewer than {which} messages in its first chunk'
    if struct.unpack_from('<I', data, body + 24)[0]:
        struct.pack_into('<I', data, body + 24, zlib.crc32(bytes(data[first:first + rlen])))
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_bytes(bytes(data))
    return dst


def two_topics(bag: Path, *, storage: str, times: Sequence[int] = (10, 20, 30)) -> tuple[Connection, Connection]:
    """A rosbag2 ``bag`` of two String topics, /a at ``times`` and /b a nanosecond after each: their
    connections."""
    with BagWriter(bag, storage=storage) as writer:
        a, b = (writer.add_topic(t, 'std_msgs/msg/String') for t in ('/a', '/b'))
        for t in times:
            writer.write(a, t, STRING)
            writer.write(b, t + 1, STRING)
    return a, b


def without_channel_counts(path: Path) -> Path:
    """The mcap file ``path`` (as rosbags writes it: one statistics record, its summary offsets after
    it) rewritten with its statistics' per-channel map empty, which the mcap spec reads as "not
    available"; the summary's offsets and the footer moved to match, its checksum left out."""
    data = bytearray(path.read_bytes())
    footer = len(data) - 37  # the footer record, then the closing magic
    summary, offsets = struct.unpack_from('<QQ', data, footer + 9)
    pos = summary
    while data[pos] != 0x0B:
        pos += 9 + struct.unpack_from('<Q', data, pos + 1)[0]
    (length,) = struct.unpack_from('<Q', data, pos + 1)
    at = pos + 9 + 8 + 2 + 4 * 4 + 8 + 8  # the map's byte length, after the fixed fields
    (cut,) = struct.unpack_from('<I', data, at)
    del data[at + 4:at + 4 + cut]
    struct.pack_into('<I', data, at, 0)
    struct.pack_into('<Q', data, pos + 1, length - cut)
    footer -= cut
    struct.pack_into('<QI', data, footer + 17, offsets - cut, 0)
    pos = offsets - cut
    while pos < footer:  # the summary offset of the statistics group: its length
        if data[pos] == 0x0E and data[pos + 9] == 0x0B:
            struct.pack_into('<Q', data, pos + 18, struct.unpack_from('<Q', data, pos + 18)[0] - cut)
        pos += 9 + struct.unpack_from('<Q', data, pos + 1)[0]
    path.write_bytes(bytes(data))
    return path
