"""A rosbag2's sqlite3 storage read and written a batch of rows at a time: its messages as rows
(``records``), in the order rosbags' reader yields them (its own query), and rows inserted with
the statement rosbags' writer executes. What ``restamp_bag`` uses to copy a sqlite3 bag with no
Python work per message but the restamp and sqlite's own (docs/bags.md, "Speed")."""

from __future__ import annotations

from collections.abc import Collection, Iterator
from itertools import islice
from pathlib import Path

import apsw
import numpy as np
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

from evsync_ros.bag.records import ROW_CHANNEL, ROW_LENGTH, ROW_LOG, ROW_OFFSET, Chunk
from evsync_ros.errors import BagError, unreadable

__all__ = ['BATCH_ROWS', 'batches', 'connect', 'integer_times', 'messages']

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
    stop)) in the storage file of ``dbconn`` (``BagReader.rows``), as rosbags' ``Sqlite3Reader.messages``
    yields them, unchecked; BagError naming ``name`` when the database cannot be read."""
    query, args = _query(tuple(set(topic_ids)), window)
    try:
        yield from dbconn.execute(query, args)
    except Exception as exc:  # apsw's errors on a corrupt database, whatever their class
        raise unreadable(name, exc) from exc


def batches(dbconn: apsw.Connection, topic_ids: Collection[int], *, name: str, size: int = BATCH_ROWS
            ) -> Iterator[Chunk]:
    """The messages of ``topic_ids`` in the storage file of ``dbconn`` (``BagReader.rows``), ``size``
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
