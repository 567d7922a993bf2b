"""A rosbag2's mcap storage files, read and written a chunk at a time (``reader.PLUGINS``): their
Message records as rows (``records``), in the order rosbags' reader yields them, and chunks of
records written into rosbags' mcap writer as its own ``close_chunk`` writes them. What ``BagReader``
reads an mcap file through, and ``restamp_bag`` copies an mcap bag into an mcap output with, with no
Python work per message but the restamp (docs/bags.md, "Reading a bag")."""

from __future__ import annotations

import struct
import zlib
from collections import defaultdict
from collections.abc import Collection, Iterator
from io import BytesIO
from typing import BinaryIO

import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Connection
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.storage_mcap import ChunkInfo, McapReader, McapWriter, PendingChunk, decompress, read_exact

from evsync_ros.bag import _records
from evsync_ros.bag.files import Part
from evsync_ros.bag.records import ROW_CHANNEL, ROW_LENGTH, ROW_LOG, ROW_OFFSET, Chunk, among, read_into
from evsync_ros.errors import BagError

__all__ = ['McapPlugin', 'chunks', 'in_order', 'write_chunk']

_CHUNK_FIXED = struct.Struct('<QQQIIQ')
"""A Chunk record's fields before its data: message start and end time, uncompressed size, CRC (0),
compression's length (0: none), compressed size."""


def _read(storage: McapReader, ids: Collection[int]) -> list[ChunkInfo]:
    """The chunks rosbags' reader reads for channels ``ids`` (those that count a message of one), in
    file order."""
    return sorted((c for c in storage.chunks if any(c.channel_count.get(i, 0) for i in ids)),
                  key=lambda c: c.chunk_start_offset)


def in_order(storage: McapReader, ids: Collection[int]) -> bool:
    """Whether reading the chunks of ``storage`` that hold channels ``ids`` one after another in file
    order yields their messages in the order rosbags' reader does (a merge of the chunks by log
    time, ties to the earlier chunk): the file is indexed, each chunk's span is a span of int64
    times, and none begins before every chunk before it has ended."""
    if not storage.chunks:
        return False
    ended = -1
    for c in _read(storage, ids):
        if not 0 <= c.message_start_time <= c.message_end_time < 1 << 63 or c.message_start_time < ended:
            return False
        ended = max(ended, c.message_end_time)
    return True


def chunks(storage: McapReader, ids: Collection[int], *, name: str) -> Iterator[Chunk]:
    """Each chunk of ``storage`` that rosbags' reader reads for channels ``ids`` (``in_order``), in file
    order, with the rows it yields of them: channels ``ids``, log times within the chunk's span in
    the index, sorted by log time (stably), as rosbags' ``msgsrc`` does; BagError naming ``name``
    for a chunk that is corrupt. An uncompressed chunk is read into one buffer, kept from chunk to
    chunk (fresh pages cost more than the copy)."""
    assert storage.bio is not None
    bio = storage.bio
    buffer = bytearray()
    wanted = sorted(ids)
    for info in _read(storage, ids):
        try:
            bio.seek(info.chunk_start_offset + 9 + 24)
            (crc,) = struct.unpack('<I', read_exact(bio, 4))
            bio.seek(info.chunk_start_offset + 9 + 40 + len(info.compression))
            if info.compression or info.compressed_size != info.uncompressed_size:
                data: memoryview | bytes = decompress(read_exact(bio, info.compressed_size), info.compression,
                                                      info.uncompressed_size, crc)
            else:
                buffer, data = _read_into(bio, buffer, info.compressed_size, crc)
            rows = np.frombuffer(_records.message_records(data), np.int64).reshape(-1, 4)
        except Exception as exc:  # rosbags', zstd's, lz4's errors on a corrupt chunk, whatever their class
            raise BagError(f'{name}: chunk at byte {info.chunk_start_offset} cannot be read ({exc}); the '
                           'storage file is corrupt or truncated') from exc
        unsigned = rows[:, ROW_LOG].view(np.uint64)  # mcap's log times are
        rows = rows[among(rows[:, ROW_CHANNEL], wanted) & (unsigned >= info.message_start_time)
                    & (unsigned <= info.message_end_time)]
        logs = rows[:, ROW_LOG]
        if logs.size > 1 and np.any(logs[1:] < logs[:-1]):
            rows = rows[np.argsort(logs, kind='stable')]
        yield Chunk(data, rows)


def _read_into(bio: BinaryIO, buffer: bytearray, size: int, crc: int) -> tuple[bytearray, memoryview]:
    """(buffer, view): ``size`` bytes of ``bio`` read into ``buffer`` (``records.read_into``), checked
    against ``crc`` as rosbags checks a chunk (0: none); ReaderError when the file ends first."""
    buffer, view = read_into(bio, buffer, size)
    if len(view) != size:
        raise ReaderError(f'Truncated record: expected {size} bytes, got {len(view)}.')
    if crc and zlib.crc32(view) != crc:
        raise ReaderError('Chunk checksum mismatch.')
    return buffer, view


def write_chunk(storage: McapWriter, records: bytes | memoryview, channels: npt.NDArray[np.int64],
                logs: npt.NDArray[np.int64], offsets: npt.NDArray[np.int64]) -> None:
    """Write ``records`` (``build``'s; their channel ids, log times and offsets) as one chunk of
    ``storage``, with its message indexes and its entry for the summary, as ``McapWriter.close_chunk``
    writes a chunk of the same records; the schemas and channels added since the last chunk go first,
    as there. The writer's own statistics count the messages."""
    pending = storage.chunk
    if pending.msgs:  # messages written one at a time before: their chunk is closed first
        storage.close_chunk()
        pending = storage.chunk
    head = pending.bio.getvalue()
    if head:
        records, offsets = head + bytes(records), offsets + len(head)
    start, end = int(logs.min()), int(logs.max())
    storage.message_start_time = min(start, storage.message_start_time)
    storage.message_end_time = max(end, storage.message_end_time)
    ids, first, counts = np.unique(channels, return_index=True, return_counts=True)
    for cid, count in zip(ids.tolist(), counts.tolist()):
        storage.channel_stats[cid] += count
    bio = storage.bio
    chunk_start = bio.tell()
    fixed = _CHUNK_FIXED.pack(start, end, len(records), 0, 0, len(records))
    bio.write(b'\x06' + struct.pack('<Q', len(fixed) + len(records)) + fixed)
    bio.write(records)
    chunk_end = bio.tell()
    indexes = []
    for cid in ids[np.argsort(first)].tolist():  # in the order the chunk's channels first appear
        mine = channels == cid
        entries = np.empty((int(mine.sum()), 2), '<u8')
        entries[:, 0], entries[:, 1] = logs[mine], offsets[mine]
        indexes.append((cid, bio.tell()))
        body = entries.tobytes()
        bio.write(b'\x07' + struct.pack('<QHI', 6 + len(body), cid, len(body)) + body)
    summary = BytesIO()
    summary.write(struct.pack('<QQQQI', start, end, chunk_start, chunk_end - chunk_start, 10 * len(indexes)))
    for cid, at in indexes:
        summary.write(struct.pack('<HQ', cid, at))
    summary.write(struct.pack('<QIQQ', bio.tell() - chunk_end, 0, len(records), len(records)))
    storage.chunks.append(summary)
    storage.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))


class McapPlugin:
    """``BagReader``'s reads of an mcap file (``reader.Plugin``). The file is read at its offsets
    through the bag's own reader, which a forked process may share."""

    def messages(self, part: Part, *, window: tuple[int, int] | None, native: bool
                 ) -> Iterator[tuple[Connection, int, bytes]]:
        """The file's messages a chunk at a time where ``chunks`` can and no ``window`` is given, else
        through rosbags' reader of the file (which reads a window's chunks and rows alone, and takes a
        window's messages whatever a chunk's index says)."""
        chunked = self.chunks(part) if window is None else None
        if chunked is None:
            start, stop = window if window is not None else (None, None)
            storage = part.file
            assert isinstance(storage, McapReader)
            for conn, timestamp, data in storage.messages([c for c in storage.connections if c.id in part.conns],
                                                          start, stop):
                yield part.conns[conn.id], timestamp, data
            return
        conns = part.conns
        for chunk in chunked:
            held = chunk.data
            for offset, length, log, cid in chunk.rows[:, [ROW_OFFSET, ROW_LENGTH, ROW_LOG, ROW_CHANNEL]].tolist():
                yield conns[cid], log, bytes(held[offset:offset + length])

    def chunks(self, part: Part) -> Iterator[Chunk] | None:
        """The file's chunks in file order where that is rosbags' reader's order (``in_order``); None
        otherwise."""
        assert isinstance(part.file, McapReader)
        if not in_order(part.file, part.conns):
            return None
        return chunks(part.file, part.conns, name=str(part.path))
