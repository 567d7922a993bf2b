"""A chunk's message records as rows of int64 (their data's place, record time, topic id), walked and
built in C (``_records``): what ``mcapchunks`` and ``ros1chunks`` read and write, and what
``restamp_bag`` restamps a chunk at a time."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from io import BufferedIOBase
from typing import BinaryIO, cast

import numpy as np
import numpy.typing as npt

from evsync_ros.bag import _records

__all__ = ['NO_STAMP', 'ROW_CHANNEL', 'ROW_LENGTH', 'ROW_LOG', 'ROW_OFFSET', 'Chunk', 'Rows', 'among', 'blobs', 'build',
           'pack', 'read_into', 'unpacked']

ROW_OFFSET, ROW_LENGTH, ROW_LOG, ROW_CHANNEL = range(4)
"""The columns of a chunk's rows: its data's offset and length in the chunk, record time (an mcap
log time), channel or connection id."""

Rows = npt.NDArray[np.int64]


@dataclass(frozen=True)
class Chunk:
    """One input chunk: its uncompressed records and their message rows, in reading order. ``data``
    is the reader's buffer, good until the next chunk is read; ``blobs``: each row's message as read,
    where the reader has them as objects (sqlite3's rows)."""

    data: memoryview | bytes
    rows: Rows
    blobs: list[bytes] | None = None


_FEW = 12
NO_STAMP = np.iinfo(np.int64).min
"""In ``build``'s stamps: the message's header.stamp stays."""


def build(chunk: Chunk, rows: Rows, logs: npt.NDArray[np.int64], stamps: npt.NDArray[np.int64],
          new: list[bytes | bytearray | None], *, out: bytearray | memoryview, ros1: bool = False
          ) -> tuple[int, npt.NDArray[np.int64] | None]:
    """(size, offsets): into ``out``, a message record for each of ``rows`` (ids as they are to be
    written), record time ``logs``, data ``new[i]`` or else the chunk's own with header.stamp
    ``stamps[i]`` unless that is ``NO_STAMP``, as rosbags writes one: an mcap Message (sequence 0,
    publish time the log time) or with ``ros1`` a ROS 1 message record; size: the bytes they take;
    offsets: where each record begins. A bytearray ``out`` is grown when it is too small (a buffer
    kept from chunk to chunk); a fixed one is not: offsets is None and nothing is written."""
    size, offsets = _records.build_chunk(chunk.data, np.ascontiguousarray(rows), np.ascontiguousarray(logs),
                                         np.ascontiguousarray(stamps), new, out, ros1)
    return size, None if offsets is None else np.frombuffer(offsets, np.int64)


def pack(chunk: Chunk, rows: Rows, stamps: npt.NDArray[np.int64], new: list[bytes | bytearray | None], *,
         out: bytearray | memoryview) -> tuple[int, npt.NDArray[np.int64] | None]:
    """(size, lengths): ``blobs`` of ``rows`` one after another into ``out`` (sqlite3 rows handed from
    one process to another, ``unpacked``); size: the bytes they take. A bytearray ``out`` is grown
    when it is too small; a fixed one is not: lengths is None and nothing is written."""
    made = blobs(chunk, rows, stamps, new)
    lengths = np.fromiter(map(len, made), np.int64, len(made))
    size = int(lengths.sum())
    if len(out) < size:
        if not isinstance(out, bytearray):
            return size, None
        out.extend(bytes(size - len(out)))
    at = 0
    for blob, n in zip(made, lengths.tolist()):
        out[at:at + n] = blob
        at += n
    return size, lengths


def unpacked(data: memoryview | bytes, lengths: npt.NDArray[np.int64]) -> list[memoryview]:
    """The blobs ``pack`` wrote into ``data``, as views of it."""
    view = memoryview(data)
    ends = np.cumsum(lengths)
    return [view[a:b] for a, b in zip((ends - lengths).tolist(), ends.tolist())]


def read_into(src: BinaryIO, buffer: bytearray, size: int) -> tuple[bytearray, memoryview]:
    """(buffer, view): up to ``size`` bytes of ``src`` read into ``buffer``, a buffer kept from chunk
    to chunk (fresh pages cost more than the read; a new one when it is too small: the last chunk
    may still be viewed); the view is shorter than ``size`` when ``src`` ends first."""
    if len(buffer) < size:
        buffer = bytearray(max(size, 2 * len(buffer)))
    view = memoryview(buffer)[:size]
    got = cast('BufferedIOBase', src).readinto(view) or 0
    return buffer, view[:got] if got < size else view


def among(values: npt.NDArray[np.int64], ids: Iterable[int]) -> npt.NDArray[np.bool_]:
    """``np.isin(values, ids)``, a comparison per id for the few ids a chunk's topics have (isin's own
    work costs more than the comparisons below a dozen)."""
    ids = list(ids)
    if len(ids) > _FEW:
        return np.isin(values, ids)
    mask = np.zeros(values.shape, bool)
    for i in ids:
        mask |= values == i
    return mask


def blobs(chunk: Chunk, rows: Rows, stamps: npt.NDArray[np.int64], new: list[bytes | bytearray | None]
          ) -> list[bytes | bytearray]:
    """Each of ``rows``' messages as an object to insert (a sqlite3 row's blob): ``new[i]``, or the
    chunk's own with header.stamp ``stamps[i]`` unless that is ``NO_STAMP`` (as ``build`` writes
    it), or else the message as read (``chunk.blobs``), not copied."""
    return _records.blobs(chunk.data, np.ascontiguousarray(rows), np.ascontiguousarray(stamps), new, chunk.blobs)
