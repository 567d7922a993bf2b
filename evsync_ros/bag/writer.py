"""Writing rosbag2 recordings, and ROS 1 bags, with rosbags, so that a partial output never looks
complete.

``BagWriter`` writes into a hidden temporary directory beside the destination,
``.NAME.PID.XXXX.partial``, and renames it into place only when the ``with`` block ends without an
exception; on any failure the temporary directory is removed, and a failure to write (a full disk,
a file size limit) is a ``BagError`` naming the destination. A process killed outright (SIGKILL)
cannot clean up: its partial directory stays hidden, never at the destination, and the next
``BagWriter`` for the same destination removes it once its process is gone. Nothing is synced to
the disk (as ``cp`` syncs nothing): after an operating system crash or a power cut, an output
renamed into place shortly before may have lost what the kernel had not yet written. An existing
destination is never overwritten. Storage ``ros1`` writes a ROS 1 bag (one ``.bag`` file, renamed
into place the same way); ``write`` takes CDR and converts it, ``write_ros1`` takes ROS 1 bytes.

A rosbag2's messages go into rosbags' storage in batches (``_Sqlite3Rows``, ``_McapRecords``): the
same rows and records, in the same order, as rosbags' ``Writer.write`` makes one message at a time,
without its Python work per message (docs/bags.md, "Speed").
"""

from __future__ import annotations

import glob
import json
import os
import shutil
import sqlite3
import struct
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Connection, Qos
from rosbags.rosbag1 import WriterError as Ros1WriterError
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionMode
from rosbags.rosbag2.errors import WriterError
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer
from rosbags.serde import SerdeError
from rosbags.typesys.store import Typestore

from evsync_ros.bag import mcapchunks, ros1
from evsync_ros.bag.reader import PROVENANCE_KEY
from evsync_ros.bag.ros1chunks import ChunkedWriter as Ros1Writer
from evsync_ros.errors import BagError
from msg_adapters.definitions import event_typestore
from msg_adapters.errors import MessageError

STORAGES = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}
"""The rosbag2 storages."""
ROS1 = 'ros1'
"""The storage of a ROS 1 bag."""
_WRITE_ERRORS = (WriterError, Ros1WriterError, OSError, sqlite3.Error)


BATCH_MESSAGES = 1024
"""Messages held at most before a batch goes into sqlite3 (``BATCH_BYTES`` too)."""
BATCH_BYTES = 8 << 20


class _Sqlite3Rows:
    """Rows for rosbags' sqlite3 storage, inserted a batch at a time with the statement its
    ``Sqlite3Writer.write`` executes once per message: the same rows in the same order, in the one
    transaction rosbags commits on closing."""

    INSERT = 'INSERT INTO messages (topic_id, timestamp, data) VALUES(?, ?, ?)'

    def __init__(self, storage: Sqlite3Writer) -> None:
        # no fsync at the commit and the journal in memory, as rosbag2's own sqlite3 storage writes by
        # default: an output is renamed into place only once complete, and the other storages' are
        # not synced either; the file's bytes are the same
        storage.conn.execute('PRAGMA synchronous = OFF')
        storage.conn.execute('PRAGMA journal_mode = MEMORY')
        self.cursor = storage.cursor
        self.rows: list[tuple[int, int, bytes]] = []
        self.nbytes = 0

    def add(self, cid: int, timestamp: int, data: bytes | bytearray | memoryview) -> None:
        # held until the batch goes in: a copy, unless bytes (which no caller can change meanwhile)
        held = data if type(data) is bytes else bytes(data)
        self.rows.append((cid, timestamp, held))
        self.nbytes += len(held)
        if len(self.rows) >= BATCH_MESSAGES or self.nbytes >= BATCH_BYTES:
            self.flush()

    def flush(self) -> None:
        if self.rows:
            self.cursor.executemany(self.INSERT, self.rows)
            self.rows, self.nbytes = [], 0

    def add_rows(self, topic_ids: list[int], timestamps: list[int], data: Sequence[bytes | bytearray | memoryview]
                 ) -> None:
        """Many rows at once, after those held: the same statement, the same rows in the same order."""
        self.flush()
        self.cursor.executemany(self.INSERT, zip(topic_ids, timestamps, data))


_MESSAGE_RECORD = struct.Struct('<BQHIQQ')
"""An mcap Message record's opcode (0x05), length, and fields before its data: channel id, sequence,
log time, publish time (little endian)."""


class _McapRecords:
    """Message records written straight into rosbags' pending mcap chunk: the bytes and index entries
    its ``McapWriter.write`` makes (sequence 0, log and publish time the record time), without a
    BytesIO and six calls per message; a chunk closes past 1 MiB as there, by rosbags' own code."""

    CHUNK_BYTES = 1 << 20

    def __init__(self, storage: McapWriter) -> None:
        self.storage = storage

    def add(self, cid: int, timestamp: int, data: bytes | bytearray | memoryview) -> None:
        st = self.storage
        st.message_start_time = min(timestamp, st.message_start_time)
        st.message_end_time = max(timestamp, st.message_end_time)
        st.channel_stats[cid] += 1
        chunk = st.chunk
        chunk.message_start_time = min(timestamp, chunk.message_start_time)
        chunk.message_end_time = max(timestamp, chunk.message_end_time)
        bio = chunk.bio
        chunk.msgs[cid].append((timestamp, bio.tell()))
        bio.write(_MESSAGE_RECORD.pack(0x05, 22 + len(data), cid, 0, timestamp, timestamp))
        bio.write(data)
        if bio.tell() > self.CHUNK_BYTES:
            st.close_chunk()

    def flush(self) -> None:
        """Nothing is held: a chunk is rosbags' to close."""


def _batched(writer: Writer) -> _Sqlite3Rows | _McapRecords | None:
    """What writes a rosbag2 writer's messages in batches (None: its own ``write``, message by message,
    for a storage or compression these do not know)."""
    if writer.compression_mode != CompressionMode.NONE:
        return None
    if type(writer.storage) is Sqlite3Writer:
        return _Sqlite3Rows(writer.storage)
    if type(writer.storage) is McapWriter:
        return _McapRecords(writer.storage)
    return None


def remove_stale_partials(path: Path) -> list[Path]:
    """Remove the partial directories that writers of ``path`` killed outright left behind (their
    process is gone); a live writer's is kept. Returns what was removed."""
    removed = []
    for partial in path.parent.glob(f'.{glob.escape(path.name)}.*.partial'):
        pid = partial.name[len(path.name) + 2:].split('.', 1)[0]
        if not pid.isdigit() or _alive(int(pid)):
            continue
        shutil.rmtree(partial, ignore_errors=True)
        removed.append(partial)
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class BagWriter:
    """``with BagWriter(path, storage='mcap') as w: c = w.add_topic(...); w.write(c, t, raw)``."""

    def __init__(self, path: str | Path, *, storage: str = 'sqlite3', typestore: Typestore | None = None) -> None:
        """``storage``: 'sqlite3', 'mcap' or 'ros1' (a ROS 1 bag, whose name must end in .bag);
        ``typestore``: the types of what is written, to convert CDR to ROS 1 (default: the event
        types and ROS 2 Jazzy's)."""
        self.path = Path(path)
        if storage not in (*STORAGES, ROS1):
            raise BagError(f'{self.path}: storage must be one of {", ".join((*STORAGES, ROS1))}, got {storage!r}')
        if (storage == ROS1) != ros1.is_ros1(self.path):
            raise BagError(f'{self.path}: a ROS 1 bag is a file ending in {ros1.SUFFIX}, and only a ROS 1 bag is '
                           f'(storage {storage!r})')
        if self.path.exists():
            raise BagError(f'{self.path}: exists already; refusing to overwrite it')
        if not self.path.parent.is_dir():
            raise BagError(f'{self.path}: parent directory {self.path.parent} does not exist')
        self.storage = storage
        self._typestore = typestore
        self._tmpdir: Path | None = None
        self._writer: Writer | Ros1Writer | None = None
        self._batch: _Sqlite3Rows | _McapRecords | None = None
        self._topics: dict[int, Connection] = {}
        """A rosbag2's topics by id: what ``write`` takes."""
        self.removed_stale: list[Path] = []
        """Partial outputs of killed writers of this destination, removed on entering."""

    @property
    def typestore(self) -> Typestore:
        """The types of what is written (made at first use when none was given: the event types and
        ROS 2 Jazzy's take a twentieth of a second to make)."""
        return self._typestore if self._typestore is not None else event_typestore()

    def __enter__(self) -> BagWriter:
        self.removed_stale = remove_stale_partials(self.path)
        self._tmpdir = Path(tempfile.mkdtemp(prefix=f'.{self.path.name}.{os.getpid()}.', suffix='.partial',
                                             dir=self.path.parent))
        try:
            if self.storage == ROS1:
                self._writer = Ros1Writer(self._tmpdir / self.path.name)
            else:
                self._writer = Writer(self._tmpdir / self.path.name, version=9, storage_plugin=STORAGES[self.storage])
            self._writer.open()
            if isinstance(self._writer, Writer):
                self._batch = _batched(self._writer)
        except _WRITE_ERRORS as exc:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            raise BagError(f'{self.path}: cannot open for writing: {exc}') from exc
        except BaseException:  # Ctrl-C, SIGTERM as it opens: __exit__ will not run, so nothing to clean up later
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            raise
        return self

    def add_topic(self, topic: str, msgtype: str, *, msgdef: str | None = None, rihs01: str | None = None,
                  serialization_format: str = 'cdr', offered_qos_profiles: Sequence[Qos] = (),
                  md5sum: str | None = None, latching: bool = False) -> Connection:
        """A topic of the output: its definition and hash as given (an input's, carried over), or
        generated from the event typestore when ``msgdef`` is None. A ROS 1 bag's topic takes its
        ROS 1 definition and ``md5sum`` (both or neither: then generated from the typestore) and
        ``latching``; ``rihs01``, the serialization and the QoS are rosbag2's."""
        assert self._writer is not None, 'use BagWriter in a with block'
        if isinstance(self._writer, Ros1Writer):
            if msgdef is None or md5sum is None:
                msgdef, md5sum = ros1.definition(self.typestore, msgtype)
            return self._writer.add_connection(topic, msgtype, msgdef=msgdef, md5sum=md5sum, latching=int(latching))
        kwargs = {'msgdef': msgdef, 'rihs01': rihs01} if msgdef is not None else {'typestore': event_typestore()}
        conn = self._writer.add_connection(topic, msgtype, serialization_format=serialization_format,
                                           offered_qos_profiles=offered_qos_profiles, **kwargs)
        self._topics[conn.id] = conn
        return conn

    def set_provenance(self, record: Mapping[str, Any]) -> bool:
        """Record ``record`` (JSON) in a rosbag2's metadata, ``custom_data`` key ``evsync``; False for a
        ROS 1 bag, whose format has no place for it."""
        assert self._writer is not None, 'use BagWriter in a with block'
        if isinstance(self._writer, Ros1Writer):
            return False
        self._writer.set_custom_data(PROVENANCE_KEY, json.dumps(record, sort_keys=True))
        return True

    def write(self, connection: Connection, timestamp_ns: int, raw: bytes | bytearray | memoryview) -> None:
        """Write one CDR message (converted for a ROS 1 bag); BagError naming the destination when
        writing fails."""
        assert self._writer is not None, 'use BagWriter in a with block'
        if isinstance(self._writer, Ros1Writer):
            try:
                raw = ros1.to_ros1(self.typestore, raw, connection.msgtype)
            except (SerdeError, MessageError) as exc:
                raise BagError(f'{self.path}: a message of {connection.topic} cannot be written as ROS 1 '
                               f'{connection.msgtype} ({exc})') from exc
            self.write_ros1(connection, timestamp_ns, raw)
            return
        timestamp = int(timestamp_ns)
        self._check_unsigned(connection.topic, timestamp)
        try:
            if self._batch is not None and self._topics.get(connection.id) is connection:
                self._batch.add(connection.id, timestamp, raw)
                self._count(connection.id, timestamp)
            else:  # rosbags' own write: its checks (an unknown connection), its storage
                self._writer.write(connection, timestamp, bytes(raw) if isinstance(raw, bytearray) else raw)
        except _WRITE_ERRORS as exc:
            raise BagError(f'{self.path}: writing failed ({exc}); nothing is left at {self.path}') from exc

    @property
    def takes_chunks(self) -> bool:
        """Whether ``write_chunk`` (``write_rows`` when ``takes_rows``) can write: a ROS 1 bag, or an
        uncompressed rosbag2 whose storage rosbags writes."""
        return self._batch is not None or isinstance(self._writer, Ros1Writer)

    @property
    def takes_rows(self) -> bool:
        """Whether the output takes messages as rows (``write_rows``): sqlite3."""
        return isinstance(self._batch, _Sqlite3Rows)

    def write_rows(self, topic_ids: npt.NDArray[np.int64], timestamps: npt.NDArray[np.int64],
                   data: Sequence[bytes | bytearray | memoryview]) -> None:
        """Write messages as sqlite3 rows (``_Sqlite3Rows.add_rows``), counted for the metadata as
        ``write`` counts each; BagError naming the destination when writing fails."""
        assert isinstance(self._batch, _Sqlite3Rows) and isinstance(self._writer, Writer), 'takes_rows first'
        try:
            self._batch.add_rows(topic_ids.tolist(), timestamps.tolist(), data)
        except _WRITE_ERRORS as exc:
            raise BagError(f'{self.path}: writing failed ({exc}); nothing is left at {self.path}') from exc
        self._count_all(topic_ids, timestamps)

    def write_chunk(self, records: bytes | memoryview, channels: npt.NDArray[np.int64], logs: npt.NDArray[np.int64],
                    offsets: npt.NDArray[np.int64]) -> None:
        """Write message records (``records.build``'s, for this storage; their topics' ids, record
        times and offsets): an mcap output's as one chunk (``mcapchunks.write_chunk``), counted for
        the metadata as ``write`` counts each message; a ROS 1 bag's into its chunks
        (``ros1chunks.ChunkedWriter.add_records``). BagError naming the destination when writing
        fails."""
        try:
            if isinstance(self._writer, Ros1Writer):
                self._writer.add_records(records, channels, logs, offsets)
                return
            assert isinstance(self._batch, _McapRecords), 'takes_chunks first'
            if logs.size and int(logs.min()) < 0:
                i = int(np.argmin(logs))
                self._check_unsigned(self._topics[int(channels[i])].topic, int(logs[i]))
            mcapchunks.write_chunk(self._batch.storage, records, channels, logs, offsets)
        except _WRITE_ERRORS as exc:
            raise BagError(f'{self.path}: writing failed ({exc}); nothing is left at {self.path}') from exc
        self._count_all(channels, logs)

    def _check_unsigned(self, topic: str, timestamp: int) -> None:
        """BagError naming the destination for a record time before 0 in an mcap output, whose times
        are unsigned (rosbags' writer would fail only on closing, with an OverflowError)."""
        if timestamp < 0 and self.storage == 'mcap':
            raise BagError(f'{self.path}: a message of {topic} has the record time {timestamp}, before 0, which an '
                           f'mcap file cannot hold (its times are unsigned); nothing is left at {self.path}')

    def _count_all(self, ids: npt.NDArray[np.int64], timestamps: npt.NDArray[np.int64]) -> None:
        """``_count`` of many messages at once."""
        writer = self._writer
        assert isinstance(writer, Writer)
        topics, counts = np.unique(ids, return_counts=True)
        for cid, count in zip(topics.tolist(), counts.tolist()):
            writer.counts[cid] += count
        writer.min_timestamp = min(int(timestamps.min()), writer.min_timestamp)
        writer.max_timestamp = max(int(timestamps.max()), writer.max_timestamp)

    def _count(self, cid: int, timestamp: int) -> None:
        """What rosbags' ``Writer.write`` counts of each message, for the metadata it writes on closing."""
        writer = self._writer
        assert isinstance(writer, Writer)
        writer.counts[cid] += 1
        writer.min_timestamp = min(timestamp, writer.min_timestamp)
        writer.max_timestamp = max(timestamp, writer.max_timestamp)

    def write_ros1(self, connection: Connection, timestamp_ns: int, raw: bytes | bytearray | memoryview) -> None:
        """Write one message of a ROS 1 bag, given as its ROS 1 bytes."""
        assert isinstance(self._writer, Ros1Writer), 'write_ros1 writes a ROS 1 bag only'
        try:
            self._writer.write(connection, int(timestamp_ns), bytes(raw) if isinstance(raw, bytearray) else raw)
        except _WRITE_ERRORS as exc:
            raise BagError(f'{self.path}: writing failed ({exc}); nothing is left at {self.path}') from exc

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        assert self._writer is not None and self._tmpdir is not None
        try:
            try:
                if exc_type is None and self._batch is not None:
                    self._batch.flush()
                self._writer.close()
            except _WRITE_ERRORS as close_exc:
                if exc_type is None:
                    raise BagError(f'{self.path}: finishing the bag failed ({close_exc}); nothing is left at '
                                   f'{self.path}') from close_exc
            if exc_type is None:
                if self.path.exists():
                    raise BagError(f'{self.path}: appeared while writing; refusing to overwrite it')
                (self._tmpdir / self.path.name).rename(self.path)
        finally:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
