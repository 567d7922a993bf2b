"""ROS 1 bags (``.bag``, format 2.0) read and written a chunk at a time (``reader.PLUGINS``).

``StreamingRos1`` reads a bag chunk by chunk in file order, one chunk in memory at a time (rosbags'
reader builds an index entry per message first: memory that grows with the recording); ``chunks``
gives each chunk's message records as rows (``records``); ``ChunkedWriter`` writes records into
rosbags' ROS 1 writer in chunks as its ``write`` would cut them, each chunk's index written from
arrays. What ``BagReader`` reads a ROS 1 bag through, and ``restamp_bag`` copies a ROS 1 bag into a
ROS 1 output with, with no Python work per message but the restamp (docs/bags.md, "Reading a
bag"). The messages' conversion to CDR and back: ``ros1``.
"""

from __future__ import annotations

import bz2
import struct
from collections import defaultdict
from collections.abc import Callable, Iterable, Iterator, Sequence
from io import BytesIO
from pathlib import Path
from typing import Any, BinaryIO, cast

import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Connection, ConnectionExtRosbag1, MessageDefinition, MessageDefinitionFormat
from rosbags.rosbag1 import Writer
from rosbags.rosbag1.reader import RecordType
from rosbags.rosbag1.writer import Header, WriteChunk

from evsync_ros.bag import _records, records, ros1
from evsync_ros.bag.files import Part
from evsync_ros.bag.records import Chunk
from evsync_ros.errors import BagError

__all__ = ['ChunkedWriter', 'Ros1Plugin', 'StreamingRos1', 'chunks']

_OP_MESSAGE, _OP_BAG_HEADER, _OP_INDEX, _OP_CHUNK, _OP_CHUNK_INFO, _OP_CONNECTION = 2, 3, 4, 5, 6, 7
_DECOMPRESS: dict[str, Callable[[bytes], bytes]] = {'none': bytes, 'bz2': bz2.decompress}


def _decompressor(name: str, path: Path) -> Callable[[bytes], bytes]:
    if name == 'lz4' and name not in _DECOMPRESS:
        from lz4.frame import decompress  # type: ignore[import-untyped]  # rosbags' own dependency

        _DECOMPRESS['lz4'] = decompress
    try:
        return _DECOMPRESS[name]
    except KeyError:
        raise BagError(f'{path}: chunk compression {name!r} is not supported') from None


def _fields(blob: bytes, path: Path) -> dict[str, bytes]:
    """A record header's name=value fields."""
    out, pos = {}, 0
    while pos < len(blob):
        if pos + 4 > len(blob):
            raise BagError(f'{path}: a record header is cut short (damaged bag)')
        (size,) = struct.unpack_from('<I', blob, pos)
        pos += 4
        name, sep, value = blob[pos:pos + size].partition(b'=')
        if not sep or pos + size > len(blob):
            raise BagError(f'{path}: a record header field cannot be read (damaged bag)')
        out[name.decode(errors='replace')] = value
        pos += size
    return out


def _record(src: BinaryIO, path: Path) -> tuple[dict[str, bytes], bytes] | None:
    """The next (header fields, data) of ``src``; None at its end."""
    head = _record_head(src, path)
    if head is None:
        return None
    fields, size = head
    return fields, _record_data(src, size, path)


def _record_head(src: BinaryIO, path: Path) -> tuple[dict[str, bytes], int] | None:
    """The next record's (header fields, data length) of ``src``, which is left at its data; None at its end."""
    head = src.read(4)
    if not head:
        return None
    if len(head) < 4:
        raise BagError(f'{path}: the file ends inside a record (truncated bag)')
    (hlen,) = struct.unpack('<I', head)
    blob = src.read(hlen)
    size = src.read(4)
    if len(blob) < hlen or len(size) < 4:
        raise BagError(f'{path}: the file ends inside a record (truncated bag)')
    return _fields(blob, path), int(struct.unpack('<I', size)[0])


def _record_data(src: BinaryIO, size: int, path: Path) -> bytes:
    """A record's ``size`` bytes of data, ``src`` at them."""
    data = src.read(size)
    if len(data) < size:
        raise BagError(f'{path}: the file ends inside a record (truncated bag)')
    return data


def _op(fields: dict[str, bytes]) -> int:
    return fields.get('op', b'\xff')[0]


def _u32(fields: dict[str, bytes], name: str) -> int:
    return int(struct.unpack('<I', fields[name])[0])


def _time(value: bytes) -> int:
    sec, nsec = struct.unpack('<II', value)
    return sec * 1_000_000_000 + nsec


class StreamingRos1:
    """A ROS 1 bag read chunk by chunk in file order (the order it was recorded in), holding one chunk
    at a time: memory follows the chunk size, not the message count. ``connections`` (with message
    counts) and the time span come from the index at the end of the file; BagError naming the file
    for an unindexed, truncated or damaged bag."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.connections: list[Connection] = []
        self.start_time = self.end_time = 0
        self.message_count = 0
        self._data_start = 0
        self._index_pos = 0

    def open(self) -> None:
        p = self.path
        with p.open('rb') as src:
            if src.readline() != b'#ROSBAG V2.0\n':
                raise BagError(f'{p}: not a ROS 1 bag (format 2.0)')
            rec = _record(src, p)
            if rec is None or _op(rec[0]) != _OP_BAG_HEADER:
                raise BagError(f'{p}: no bag header record (damaged bag)')
            fields = rec[0]
            self._data_start = src.tell()
            self._index_pos = int(struct.unpack('<Q', fields['index_pos'])[0])
            if self._index_pos == 0:
                raise BagError(f'{p}: not indexed (a recorder stopped before writing its index); run '
                               '`rosbag reindex` on a copy of it')
            conns, chunks = _u32(fields, 'conn_count'), _u32(fields, 'chunk_count')
            src.seek(self._index_pos)
            found: dict[int, tuple[dict[str, bytes], dict[str, bytes]]] = {}
            counts: dict[int, int] = {}
            starts, ends = [], []
            for _ in range(conns + chunks):
                rec = _record(src, p)
                if rec is None:
                    raise BagError(f'{p}: its index is cut short (damaged bag)')
                head, data = rec
                if _op(head) == _OP_CONNECTION:
                    found[_u32(head, 'conn')] = (head, _fields(data, p))
                elif _op(head) == _OP_CHUNK_INFO:
                    n = _u32(head, 'count')
                    for k in range(n):
                        cid, cnt = struct.unpack_from('<II', data, 8 * k)
                        counts[cid] = counts.get(cid, 0) + cnt
                    if n:
                        starts.append(_time(head['start_time']))
                        ends.append(_time(head['end_time']))
        unnamed = sorted((cid, n) for cid, n in counts.items() if cid not in found and n)
        if unnamed:  # their messages would be passed over unseen: a topic gone from every output
            listed = '; '.join(f'{n} messages of connection {cid}' for cid, n in unnamed)
            raise BagError(f'{p}: its index lists {listed} but no connection record for them (damaged bag)')
        self.message_count = sum(counts.values())
        self.start_time, self.end_time = (min(starts), max(ends) + 1) if starts else (0, 0)
        for cid, (head, conn) in sorted(found.items()):
            latching = conn.get('latching', b'').decode()
            self.connections.append(Connection(
                cid, _normal_topic(head['topic'].decode()), _normal_type(conn['type'].decode()),
                MessageDefinition(MessageDefinitionFormat.MSG, conn.get('message_definition', b'').decode()),
                conn.get('md5sum', b'').decode(), counts.get(cid, 0),
                ConnectionExtRosbag1(conn['callerid'].decode() if 'callerid' in conn else None,
                                     int(latching) if latching else None), self))

    def messages(self, connections: Iterable[Connection]) -> Iterator[tuple[Connection, int, bytes]]:
        """(connection, record time, ROS 1 bytes) of ``connections``' messages, in file order."""
        by_id = {c.id: c for c in connections}
        p = self.path
        for data in self.chunks():
            inner = BytesIO(data)
            while (msg := _record(inner, p)) is not None:
                mh, raw = msg
                if _op(mh) == _OP_MESSAGE and (conn := by_id.get(_u32(mh, 'conn'))) is not None:
                    yield conn, _time(mh['time']), raw

    def chunks(self) -> Iterator[bytes | memoryview]:
        """Each chunk's records, uncompressed, in file order. An uncompressed chunk is read into one
        buffer kept from chunk to chunk (``records.read_into``): its view is good until the next
        chunk is read."""
        p = self.path
        buffer = bytearray()
        with p.open('rb') as src:
            src.seek(self._data_start)
            while src.tell() < self._index_pos:
                head = _record_head(src, p)
                if head is None:
                    raise BagError(f'{p}: the file ends before its index (truncated bag)')
                fields, size = head
                compression = fields.get('compression', b'none').decode()
                if _op(fields) != _OP_CHUNK or compression != 'none':  # index data, connections; packed chunks
                    data = _record_data(src, size, p)
                    if _op(fields) == _OP_CHUNK:
                        yield _decompressor(compression, p)(data)
                    continue
                if size > self._index_pos - src.tell():  # a damaged length: refused before memory is taken
                    raise BagError(f'{p}: a chunk is longer than the file holds before its index (damaged bag)')
                buffer, view = records.read_into(src, buffer, size)
                if len(view) < size:
                    raise BagError(f'{p}: the file ends inside a record (truncated bag)')
                yield view


def _normal_topic(topic: str) -> str:
    """A topic name without repeated slashes (as rosbags names ROS 1 topics)."""
    return '/' * topic.startswith('/') + '/'.join(part for part in topic.split('/') if part)


def _normal_type(msgtype: str) -> str:
    """ROS 1 'pkg/Name' as ROS 2's 'pkg/msg/Name'."""
    pkg, _, name = msgtype.partition('/')
    return msgtype if '/msg/' in msgtype else f'{pkg}/msg/{name}'


_MAXSIZE = 2**63 - 1
_INDEX_ENTRY = np.dtype([('sec', '<u4'), ('nsec', '<u4'), ('offset', '<u4')])
"""An index entry of a ROS 1 chunk: a message's record time and where its record begins."""


def chunks(bag: StreamingRos1, conns: Iterable[int] | None = None) -> Iterator[Chunk]:
    """Each chunk of ``bag`` in file order, with the rows of the messages ``StreamingRos1.messages``
    yields of it of connections ``conns`` (default: every one of the bag); BagError naming the bag
    where that raises (a damaged chunk, record or header)."""
    known = np.array(list(conns if conns is not None else (c.id for c in bag.connections)), np.int64)
    try:
        for data in bag.chunks():
            rows = np.frombuffer(_records.ros1_message_records(data, known), np.int64).reshape(-1, 4)
            yield Chunk(data, rows)
    except BagError:
        raise
    except Exception as exc:  # a decompressor's, or a record walk's, whatever its class
        raise BagError(f'{bag.path}: cannot be read ({type(exc).__name__}: {exc}); the bag is damaged') from exc


class ChunkedWriter(Writer):
    """rosbags' ROS 1 writer, whose chunks' indexes are written from arrays (the same bytes), and
    which takes records a chunk's worth at a time (``add_records``). A chunk once written keeps only
    the count of each connection's messages, which is all its summary needs, not an entry per
    message: memory does not grow with the recording."""

    def add_records(self, records: bytes | memoryview, conns: npt.NDArray[np.int64], times: npt.NDArray[np.int64],
                    offsets: npt.NDArray[np.int64]) -> None:
        """Message records (``records.build(..., ros1=True)``; their connection ids, record times and
        offsets) into the chunks, cut where ``write`` would cut them: a chunk is written once it
        passes ``chunk_threshold`` bytes."""
        ends = np.append(offsets[1:], len(records))
        start = 0
        while start < len(offsets):
            chunk = self.chunks[-1]
            base = chunk.data.tell()
            past = base + ends[start:] - offsets[start] > self.chunk_threshold
            stop = start + int(np.argmax(past)) + 1 if past.any() else len(offsets)
            at = base + offsets[start:stop] - offsets[start]
            piece = records[offsets[start]:ends[stop - 1]]
            whole = base == 0 and bool(past.any())  # the piece is a chunk, all of it: written from where it is
            if not whole:
                chunk.data.write(piece)
            ids, first = np.unique(conns[start:stop], return_index=True)
            for cid in ids[np.argsort(first)].tolist():  # in the order the chunk's connections appear, as write
                mine = conns[start:stop] == cid
                cast('list[Any]', chunk.connections[cid]).append(np.stack([times[start:stop][mine], at[mine]], axis=1))
            chunk.start = min(chunk.start, int(times[start:stop].min()))
            chunk.end = max(chunk.end, int(times[start:stop].max()))
            if past.any():
                self.write_chunk(chunk, piece if whole else None)
            start = stop

    def write_chunk(self, chunk: WriteChunk, records: bytes | memoryview | None = None) -> None:
        """rosbags' ``write_chunk``, byte for byte, with each connection's index entries packed at once;
        ``records``: the chunk's data, where it is not in its buffer (``add_records``' whole chunk)."""
        assert self.bio
        size = len(records) if records is not None else chunk.data.tell()
        if size <= 0:
            return
        chunk.pos = self.bio.tell()
        header = Header()
        header.set_string('compression', self.compression_format)
        header.set_uint32('size', size)
        header.write(self.bio, RecordType.CHUNK)
        data = records if records is not None else chunk.data.getbuffer()
        if self.compression_format != 'none':
            data = self.compressor(bytes(data))
        self.bio.write(len(data).to_bytes(4, 'little'))
        self.bio.write(data)
        del data  # a view of the chunk's buffer: released before it is closed
        counts = {}
        for cid, items in chunk.connections.items():
            entries = _entries(items)
            header = Header()
            header.set_uint32('ver', 1)
            header.set_uint32('conn', cid)
            header.set_uint32('count', len(entries))
            header.write(self.bio, RecordType.IDXDATA)
            index = np.empty(len(entries), _INDEX_ENTRY)
            index['sec'], index['nsec'] = np.divmod(entries[:, 0], 1_000_000_000)
            index['offset'] = entries[:, 1]
            self.bio.write((len(index) * 12).to_bytes(4, 'little'))
            self.bio.write(index.tobytes())
            counts[cid] = range(len(entries))  # what close() counts, without an entry per message
        chunk.data.close()
        chunk.connections = counts  # type: ignore[assignment]
        self.chunks.append(WriteChunk(BytesIO(), -1, _MAXSIZE, 0, defaultdict(list)))


def _entries(items: Sequence[Any]) -> npt.NDArray[np.int64]:
    """A connection's index entries in a chunk, (record time, offset) rows, from what ``write`` appends
    (a tuple per message) and ``add_records`` appends (an array of rows per call), in order."""
    pieces: list[npt.NDArray[np.int64]] = []
    run: list[tuple[int, int]] = []
    for item in items:
        if isinstance(item, np.ndarray):
            if run:
                pieces.append(np.array(run, np.int64).reshape(-1, 2))
                run = []
            pieces.append(item)
        else:
            run.append(item)
    if run:
        pieces.append(np.array(run, np.int64).reshape(-1, 2))
    return np.concatenate(pieces) if pieces else np.empty((0, 2), np.int64)


class Ros1Plugin:
    """``BagReader``'s reads of a ROS 1 bag (``reader.Plugin``): a forked process may read it, as it
    opens the file anew for each read."""

    def messages(self, part: Part, *, window: tuple[int, int] | None, native: bool
                 ) -> Iterator[tuple[Connection, int, bytes]]:
        """The bag's messages chunk by chunk (``StreamingRos1.messages``), as CDR (a message that does not
        match its definition as ``ros1.Unconverted``) or, ``native``, as their own bytes; only those
        recorded in ``window`` when given."""
        bag, store = part.file, part.typestore
        assert isinstance(bag, StreamingRos1) and store is not None  # the reader made it on opening
        for conn, stamp, raw in bag.messages(part.conns.values()):
            if window is None or window[0] <= stamp < window[1]:
                yield conn, stamp, raw if native else ros1.converted(store, raw, conn.msgtype)

    def chunks(self, part: Part) -> Iterator[Chunk]:
        """The bag's chunks, each with the rows of ``part``'s connections (``chunks``)."""
        assert isinstance(part.file, StreamingRos1)
        return chunks(part.file, part.conns)
