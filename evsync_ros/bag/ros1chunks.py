"""A ROS 1 bag read and written a chunk at a time: its message records as rows (``records``), in file
order, and records written into rosbags' ROS 1 writer in chunks as its ``write`` would cut them,
each chunk's index written from arrays. What ``restamp_bag`` uses to copy a ROS 1 bag into a ROS 1
output with no Python work per message but the restamp (docs/bags.md, "Speed")."""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterator, Sequence
from io import BytesIO
from typing import Any, cast

import numpy as np
import numpy.typing as npt
from rosbags.rosbag1 import Writer
from rosbags.rosbag1.reader import RecordType
from rosbags.rosbag1.writer import Header, WriteChunk

from evsync_ros.bag import _records
from evsync_ros.bag.records import Chunk
from evsync_ros.bag.ros1 import StreamingRos1
from evsync_ros.errors import BagError

__all__ = ['ChunkedWriter', 'chunks']

_MAXSIZE = 2**63 - 1
_INDEX_ENTRY = np.dtype([('sec', '<u4'), ('nsec', '<u4'), ('offset', '<u4')])
"""An index entry of a ROS 1 chunk: a message's record time and where its record begins."""


def chunks(bag: StreamingRos1) -> Iterator[Chunk]:
    """Each chunk of ``bag`` in file order, with the rows of the messages ``StreamingRos1.messages``
    yields of it (of its connections); BagError naming the bag where that raises (a damaged chunk,
    record or header)."""
    known = np.array([c.id for c in bag.connections], np.int64)
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
