"""A rosbag2's sqlite3 storage files, read and written fast (``reader.PLUGINS``): their messages row by
row through rosbags' own query on a connection of the reading process, or a batch of rows at a time
as ``records`` rows, in the order rosbags' reader yields them; and rows inserted with the statement
rosbags' writer executes. What ``BagReader`` reads a sqlite3 file through, without rosbags' Python
work per message (docs/bags.md, "Reading a bag")."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Collection, Iterator
from itertools import islice
from pathlib import Path

import apsw
import numpy as np
from rosbags.interfaces import Connection
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

from evsync_ros.bag.files import Part
from evsync_ros.bag.records import ROW_CHANNEL, ROW_LENGTH, ROW_LOG, ROW_OFFSET, Chunk
from evsync_ros.errors import BagError, unreadable

__all__ = ['BATCH_ROWS', 'Sqlite3Plugin', 'bad_row', 'batches', 'connect', 'connection', 'int64_real',
           'integer_times', 'messages']

BATCH_ROWS = 1024
"""Rows read, restamped and inserted at a time (4,096 held 50 MB more for no speed)."""


def integer_times(storage: Sqlite3Reader, topic_ids: Collection[int]) -> bool:
    """Whether every record time of ``topic_ids``' messages is an integer, as rosbags' writer stores
    them (``batches`` gives int64 rows; rosbags' reader yields a REAL or TEXT time as it is). Asked of
    every row first, which sqlite reads from the timestamp index where the file has one (its pages,
    not the rows'); of the topics' rows only when some time is not an integer."""
    assert storage.dbconn is not None
    ids = tuple(set(topic_ids))
    anywhere = "SELECT 1 FROM messages WHERE typeof(timestamp) != 'integer' LIMIT 1"
    query = (f'SELECT 1 FROM messages WHERE topic_id IN ({",".join("?" for _ in ids)}) '
             "AND typeof(timestamp) != 'integer' LIMIT 1")
    try:
        cursor = storage.dbconn.cursor()
        return cursor.execute(anywhere).fetchone() is None or cursor.execute(query, ids).fetchone() is None
    except Exception:  # noqa: BLE001 (a database that cannot be read: rosbags' reader says what is wrong)
        return False


def connect(path: Path) -> apsw.Connection:
    """A connection of this process to a sqlite3 storage file, read only, as rosbags' reader opens one."""
    return apsw.Connection(f'file:{path}?immutable=1', flags=apsw.SQLITE_OPEN_READONLY | apsw.SQLITE_OPEN_URI)


def _query(topic_ids: tuple[int, ...], window: tuple[int, int] | None) -> tuple[str, list[int]]:
    """rosbags' ``Sqlite3Reader.messages`` query of ``topic_ids``' messages (recorded in ``window``), and
    its arguments: its order, ties included, is the one sqlite gives that query."""
    query = ('SELECT topics.id,messages.timestamp,messages.data FROM messages JOIN topics ON '
             f'messages.topic_id=topics.id WHERE topics.id IN ({",".join("?" for _ in topic_ids)})')
    args = list(topic_ids)
    if window is not None:
        query += ' AND messages.timestamp >= ? AND messages.timestamp < ?'
        args += window
    return query + ' ORDER BY timestamp', args


def messages(dbconn: apsw.Connection, topic_ids: Collection[int], *, name: str,
             window: tuple[int, int] | None = None) -> Iterator[tuple[int, object, object]]:
    """``(topic id, record time, data)`` of ``topic_ids``' messages (recorded in ``window``: [start,
    stop)) in the storage file of ``dbconn`` (``connection``), as rosbags' ``Sqlite3Reader.messages``
    yields them, unchecked; BagError naming ``name`` when the database cannot be read."""
    query, args = _query(tuple(set(topic_ids)), window)
    try:
        yield from dbconn.execute(query, args)
    except Exception as exc:  # apsw's errors on a corrupt database, whatever their class
        raise unreadable(name, exc) from exc


def batches(dbconn: apsw.Connection, topic_ids: Collection[int], *, name: str, size: int = BATCH_ROWS
            ) -> Iterator[Chunk]:
    """The messages of ``topic_ids`` in the storage file of ``dbconn`` (``connection``), ``size``
    rows at a time, in the order of rosbags' ``Sqlite3Reader.messages`` (its query: ordered by
    timestamp); BagError naming ``name`` when the database cannot be read."""
    query, args = _query(tuple(set(topic_ids)), None)
    try:
        cursor = dbconn.execute(query, args)
        while batch := list(islice(cursor, size)):
            cids, times, data = zip(*batch)
            if not all(type(d) is bytes for d in data):  # a crafted row whose data is TEXT or NULL
                cid, odd = next((c, d) for c, d in zip(cids, data) if type(d) is not bytes)
                raise BagError(f'{name}: a message of topic id {cid} is stored as {type(odd).__name__}, not bytes; '
                               'the storage file is corrupt')
            rows = np.empty((len(batch), 4), np.int64)
            rows[:, ROW_LENGTH] = np.fromiter(map(len, data), np.int64, len(data))
            rows[:, ROW_OFFSET] = np.cumsum(rows[:, ROW_LENGTH]) - rows[:, ROW_LENGTH]
            rows[:, ROW_LOG] = times
            rows[:, ROW_CHANNEL] = cids
            yield Chunk(b''.join(data), rows, blobs=list(data))
    except BagError:
        raise
    except Exception as exc:  # apsw's errors on a corrupt database, whatever their class
        raise unreadable(name, exc) from exc


INT64 = (-(1 << 63), 1 << 63)
"""The record times a rosbag2 holds: int64 nanoseconds, [least, end)."""


def int64_real(value: object) -> bool:
    """Whether ``value`` is a float within int64 nanoseconds (a sqlite3 REAL record time, read as it is)."""
    return type(value) is float and INT64[0] <= value < INT64[1]


def bad_row(bag: object, topic: str, timestamp: object, data: object) -> BagError | None:
    """The error of a crafted sqlite3 row of ``topic`` that a read cannot yield (rosbags' reader gives it
    as it is stored): its data not a BLOB, or its record time not a number of nanoseconds in int64
    (TEXT, BLOB, NULL, a REAL beyond it); None for a row rosbags' writer could have written."""
    if type(data) is not bytes:
        return BagError(f'{bag}: a message of {topic} is stored as {type(data).__name__}, not bytes; '
                        'the storage file is corrupt')
    if type(timestamp) is not int and not int64_real(timestamp):
        return BagError(f'{bag}: a message of {topic} has the record time {timestamp!r}, not a number of '
                        'nanoseconds in int64; the storage file is corrupt')
    return None


@contextlib.contextmanager
def connection(part: Part) -> Iterator[apsw.Connection]:
    """A connection to ``part``'s file that the calling process may read: the file's own in the process
    that opened the bag; in a forked process, one opened there (``connect``), closed on leaving (a
    sqlite3 connection must not cross a fork). The file alone is opened again, not the whole bag:
    rosbags' opening of a bag counts every row. (A file rosbags decompressed on opening the bag is
    its decompressed copy, read as it is.)"""
    storage = part.file
    assert isinstance(storage, Sqlite3Reader)
    if part.pid == os.getpid():
        assert storage.dbconn is not None  # the bag is open
        yield storage.dbconn
        return
    assert isinstance(storage.path, Path)  # rosbags reads a remote path only when given one
    try:
        conn = connect(storage.path)
    except Exception as exc:  # apsw's errors, whatever their class
        raise BagError(f'{part.path}: cannot open {storage.path} again ({exc})') from exc
    try:
        yield conn
    finally:
        conn.close()


class Sqlite3Plugin:
    """``BagReader``'s reads of a sqlite3 file (``reader.Plugin``)."""

    def messages(self, part: Part, *, window: tuple[int, int] | None, native: bool
                 ) -> Iterator[tuple[Connection, int, bytes]]:
        """The file's messages row by row, through rosbags' query on ``connection`` (a cursor costs less
        than ``batches``), each checked (``bad_row``)."""
        name = str(part.path)
        with connection(part) as conn:
            for cid, timestamp, data in messages(conn, part.conns, name=name, window=window):
                c = part.conns[cid]
                if type(data) is not bytes or type(timestamp) is not int:
                    error = bad_row(name, c.topic, timestamp, data)
                    if error is not None:
                        raise error
                yield c, timestamp, data  # type: ignore[misc]  # checked above

    def chunks(self, part: Part) -> Iterator[Chunk] | None:
        """The file's rows ``BATCH_ROWS`` at a time (``batches``), where every record time is an integer
        (``integer_times``, asked here: a forked process reads them); None otherwise."""
        assert isinstance(part.file, Sqlite3Reader)
        if not integer_times(part.file, part.conns):
            return None
        return self._batches(part)

    @staticmethod
    def _batches(part: Part) -> Iterator[Chunk]:
        with connection(part) as conn:
            yield from batches(conn, part.conns, name=str(part.path))
