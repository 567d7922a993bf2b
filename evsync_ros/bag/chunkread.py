"""A rosbag2's messages read a chunk at a time (``mcapchunks``, ``sqlitebatches``): the messages, order
and bytes of ``BagReader.messages``, without rosbags' reader's Python work per message; where the
chunks cannot give that order, ``BagReader.messages`` itself (docs/bags.md, "Speed")."""

from __future__ import annotations

from collections.abc import Iterator, Mapping

from rosbags.rosbag2.storage_mcap import McapReader
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

from evsync_ros.bag import mcapchunks, sqlitebatches
from evsync_ros.bag.reader import BagReader, all_mcap, int64_real
from evsync_ros.bag.records import ROW_CHANNEL, ROW_LENGTH, ROW_LOG, ROW_OFFSET, Chunk
from evsync_ros.bag.ros1 import Unconverted

__all__ = ['chunks', 'messages']


def chunks(reader: BagReader, types: Mapping[str, str]) -> Iterator[tuple[Chunk, dict[int, str]]] | None:
    """The chunks of a rosbag2's storage files that hold ``types``' topics ({topic: message type}), in
    ``BagReader.messages``' order, each with the topic of each id its rows carry (the rows of those
    topics alone): mcap files whose chunks read in order (``mcapchunks.in_order``), sqlite3 files a
    batch of rows at a time. None where that order is not the chunks' own, for a ROS 1 bag, a bag
    whose messages are compressed one by one, a file whose type of a topic is not ``types``', or a
    sqlite3 file with a record time that is not an integer (rosbags yields it as it is)."""
    return _chunks(reader, reader.storages(), types)


def _chunks(reader: BagReader, storages: list[tuple[McapReader | Sqlite3Reader, dict[int, str]]] | None,
            types: Mapping[str, str]) -> Iterator[tuple[Chunk, dict[int, str]]] | None:
    """``chunks`` of ``reader.storages()``, given."""
    if storages is None:
        return None
    wanted = [(k, s, {i: t for i, t in ids.items() if t in types}) for k, (s, ids) in enumerate(storages)]
    wanted = [(k, s, ids) for k, s, ids in wanted if ids]
    if any(not mcapchunks.in_order(s, ids) if isinstance(s, McapReader) else not sqlitebatches.integer_times(s, ids)
           for _, s, ids in wanted) or any(types[t] != _msgtype(s, i) for _, s, ids in wanted for i, t in ids.items()):
        return None
    return _read(reader, [(k, ids) for k, _, ids in wanted])


def _read(reader: BagReader, wanted: list[tuple[int, dict[int, str]]]) -> Iterator[tuple[Chunk, dict[int, str]]]:
    """The chunks of the ``wanted`` storage files (their places in ``storages()``, with their ids'
    topics) of ``reader``, read where this runs (the files are checked where the reader was opened):
    an mcap file through the bag's own reader, which a forked process may share (its chunks are
    read at their offsets), a sqlite3 file through a connection of the reading process
    (``BagReader.rows``)."""
    name = str(reader.path)
    storages = reader.storages()
    assert storages is not None  # checked by the caller
    for k, ids in wanted:
        s = storages[k][0]
        if isinstance(s, McapReader):
            for chunk in mcapchunks.chunks(s, ids, name=name):
                yield chunk, ids
            continue
        with reader.rows(s) as conn:
            for chunk in sqlitebatches.batches(conn, ids, name=name):
                yield chunk, ids


def _msgtype(storage: McapReader | Sqlite3Reader, cid: int) -> str:
    return next(c.msgtype for c in storage.connections if c.id == cid)


def messages(reader: BagReader, types: Mapping[str, str], *, window: tuple[int, int] | None = None,
             native: bool = False) -> Iterator[tuple[str, str, int, bytes | Unconverted]]:
    """``(topic, message type, record time, message)`` of ``types``' topics ({topic: message type}), as
    ``BagReader.messages(types, window=window, native=native)`` yields them (a ROS 1 bag's
    converted, or ``Unconverted``; with ``native``, its own bytes): mcap files a chunk at a time
    where ``chunks`` can and no ``window`` is given (rosbags' reader reads a window's chunks and
    rows alone, and takes a window's messages whatever a chunk's index says); sqlite3 files row by
    row through rosbags' query, on a connection of the reading process (``_rows``: a cursor costs
    less than ``sqlitebatches``' batches).

    Raises:
        BagError: a storage file turns out corrupt or truncated while it is read.
    """
    storages = reader.storages()
    chunked = _chunks(reader, storages, types) if window is None and all_mcap(storages) else None
    if chunked is None:
        rows = _rows(reader, storages, types, window)
        if rows is not None:
            yield from rows
            return
        with reader.own() as mine:  # a forked process's own reader (a ROS 1 bag, compressed messages)
            for conn, stamp, raw in mine.messages(list(types), window=window, native=native):
                yield conn.topic, conn.msgtype, stamp, raw
        return
    for chunk, topic_of in chunked:
        data = chunk.data
        columns = chunk.rows[:, [ROW_OFFSET, ROW_LENGTH, ROW_LOG, ROW_CHANNEL]].tolist()
        for offset, length, log, cid in columns:
            topic = topic_of[cid]
            yield topic, types[topic], log, bytes(data[offset:offset + length])


def _rows(reader: BagReader, storages: list[tuple[McapReader | Sqlite3Reader, dict[int, str]]] | None,
          types: Mapping[str, str], window: tuple[int, int] | None) -> Iterator[tuple[str, str, int, bytes]] | None:
    """``messages`` of a rosbag2 of sqlite3 files alone, each file's rows of ``types``' topics through
    ``BagReader.rows`` (in a forked process, a connection it opens to the file alone, not the whole
    bag again: rosbags' opening counts every row) with rosbags' own query, in ``storages()`` order
    and checked as ``BagReader.messages`` checks them; None for any other bag, or a file whose type of
    a topic is not ``types``'."""
    if storages is None or not all(isinstance(s, Sqlite3Reader) for s, _ in storages):
        return None
    wanted = [(s, {i: t for i, t in ids.items() if t in types}) for s, ids in storages]
    wanted = [(s, ids) for s, ids in wanted if ids]
    if any(types[t] != _msgtype(s, i) for s, ids in wanted for i, t in ids.items()):
        return None
    return _read_rows(reader, wanted, types, window)


def _read_rows(reader: BagReader, wanted: list[tuple[McapReader | Sqlite3Reader, dict[int, str]]],
               types: Mapping[str, str], window: tuple[int, int] | None) -> Iterator[tuple[str, str, int, bytes]]:
    name = str(reader.path)
    for s, ids in wanted:
        assert isinstance(s, Sqlite3Reader)
        with reader.rows(s) as conn:
            for cid, timestamp, data in sqlitebatches.messages(conn, ids, name=name, window=window):
                topic = ids[cid]
                if type(data) is not bytes or (type(timestamp) is not int and not int64_real(timestamp)):
                    raise reader.bad_row(topic, timestamp, data)
                yield topic, types[topic], timestamp, data  # type: ignore[misc]  # checked above
