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

A rosbag2 output can be compressed and split as ``ros2 bag record`` writes one (``Layout``): zstd
per storage file or per message, by rosbags; a new storage file once the current one holds
``max_bytes`` of messages or spans ``max_duration_ns``, which rosbags cannot do: each file is
written by a rosbags ``Writer`` of its own (``_Parts``), and the output's directory is made of
them, named ``NAME_0.db3``, ``NAME_1.db3``, ... as rosbag2 names them, with one metadata.yaml
listing them all, before it is renamed into place like any other.
"""

from __future__ import annotations

import enum
import glob
import io
import json
import os
import shutil
import sqlite3
import struct
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt
from rosbags.interfaces import Connection, Qos
from rosbags.rosbag1 import WriterError as Ros1WriterError
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.rosbag2.errors import WriterError
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer
from rosbags.serde import SerdeError
from rosbags.typesys.store import Typestore
from ruamel.yaml import YAML

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


class Compression(enum.Enum):
    """A rosbag2 output's compression, as ``ros2 bag record --compression-mode`` names it."""

    NONE = 'none'
    FILE = 'file'
    """Each storage file compressed whole, once written (``NAME.db3.zstd``)."""
    MESSAGE = 'message'
    """Each message's data compressed alone."""


COMPRESSION_MODES = tuple(c.value for c in Compression)
COMPRESSION_FORMATS = ('zstd',)
"""What rosbags compresses with (rosbag2's --compression-format; zstd is its one compressor too)."""
_ROSBAGS_MODE = {Compression.FILE: CompressionMode.FILE, Compression.MESSAGE: CompressionMode.MESSAGE}


@dataclass(frozen=True)
class Layout:
    """How a rosbag2 output's files are laid out, as ``ros2 bag record`` takes it: compression
    (``--compression-mode`` and ``--compression-format``) and splitting (``--max-bag-size`` in bytes,
    ``--max-bag-duration``; 0: not split by it). As rosbag2 splits, a storage file takes messages
    until it holds ``max_bytes`` of them (as serialized, before compression) or until the next
    message's record time is more than ``max_duration_ns`` after its earliest; that message begins
    the next file. Every file but the last so reaches the size (by less than a message)."""

    compression: Compression = Compression.NONE
    compression_format: str = ''
    max_bytes: int = 0
    max_duration_ns: int = 0

    @property
    def splits(self) -> bool:
        return bool(self.max_bytes or self.max_duration_ns)

    @property
    def plain(self) -> bool:
        """One uncompressed file: what rosbags writes by itself."""
        return self.compression is Compression.NONE and not self.splits

    def check(self, path: str | Path) -> None:
        """BagError naming ``path`` when the layout cannot be written there: a format without a mode
        or a mode without a format (rosbag2 would write that one uncompressed, unsaid), a size or
        duration below 0, or any of it for a ROS 1 bag."""
        if self.compression_format and self.compression is Compression.NONE:
            raise BagError(f'{path}: --compression-format {self.compression_format} needs a --compression-mode '
                           '(file or message)')
        if self.compression is not Compression.NONE and self.compression_format not in COMPRESSION_FORMATS:
            raise BagError(f'{path}: --compression-mode {self.compression.value} needs --compression-format '
                           f'{" or ".join(COMPRESSION_FORMATS)}')
        if self.max_bytes < 0 or self.max_duration_ns < 0:
            raise BagError(f'{path}: --max-bag-size and --max-bag-duration are 0 (no splitting) or more, got '
                           f'{self.max_bytes} bytes and {self.max_duration_ns / 1e9:g} s')
        if not self.plain and ros1.is_ros1(Path(path)):
            raise BagError(f'{path}: a ROS 1 bag (.bag) is written here as one uncompressed file; compression and '
                           'splitting are for a rosbag2 output (a name not ending in .bag)')


class _Parts:
    """The storage files of a split rosbag2 output, each written by a rosbags ``Writer`` of its own
    in ``root/0/NAME``, ``root/1/NAME``, ...: which file a message goes into (``due``), what each new
    one is given as the first was (its topics in the same order, so the same ids, and its custom
    data), and the output made of them (``assemble``)."""

    def __init__(self, root: Path, name: str, layout: Layout) -> None:
        self.root, self.name, self.layout = root, name, layout
        self.dirs: list[Path] = []
        self.topics: list[tuple[str, str, dict[str, Any]]] = []
        """Each topic's ``Writer.add_connection`` arguments, in the order they were added."""
        self.custom: dict[str, str] = {}
        self.nbytes = 0
        self.first_ns: int | None = None
        """The current file's earliest record time (None: it holds no message yet)."""

    def next_dir(self) -> Path:
        """Where the next file's ``Writer`` writes (it makes the directory)."""
        where = self.root / str(len(self.dirs)) / self.name
        where.parent.mkdir(parents=True)
        self.dirs.append(where)
        self.nbytes, self.first_ns = 0, None
        return where

    def due(self, timestamp: int) -> bool:
        """Whether a message recorded at ``timestamp`` begins a new file."""
        if self.first_ns is None:
            return False
        layout = self.layout
        return bool((layout.max_bytes and self.nbytes >= layout.max_bytes)
                    or (layout.max_duration_ns and timestamp - self.first_ns > layout.max_duration_ns))

    def add(self, timestamp: int, nbytes: int) -> None:
        self.nbytes += nbytes
        self.first_ns = timestamp if self.first_ns is None else min(self.first_ns, timestamp)

    def assemble(self, out: Path) -> list[str]:
        """The output directory ``out``: every file, renamed as rosbag2 names a split bag's
        (``NAME_0.db3``, ``NAME_1.db3.zstd``, ...), and one metadata.yaml listing them all; the files'
        names."""
        out.mkdir()
        yaml = YAML(typ='safe')
        infos, names = [], []
        for i, where in enumerate(self.dirs):
            info = yaml.load((where / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
            (own,) = info['relative_file_paths']
            names.append(f'{self.name}_{i}{own[len(self.name):]}')
            (where / own).rename(out / names[-1])
            infos.append(info)
        text = io.StringIO()
        yaml.default_flow_style = False
        yaml.dump({'rosbag2_bagfile_information': _merged(infos, names)}, text)
        (out / 'metadata.yaml').write_text(text.getvalue(), 'utf8')
        return names


def _merged(infos: list[dict[str, Any]], names: list[str]) -> dict[str, Any]:
    """One bag's metadata of its files' own (each as rosbags wrote it for its file alone, the same
    topics in the same order): the files listed under their new ``names``, counts added up, the
    span from the earliest message to the latest, the last file's custom data."""
    files = [{**f, 'path': name} for info, name in zip(infos, names) for f in info['files']]
    spans = [(f['starting_time']['nanoseconds_since_epoch'], f['duration']['nanoseconds']) for f in files
             if f['message_count']]
    start = min((t for t, _ in spans), default=infos[0]['starting_time']['nanoseconds_since_epoch'])
    end = max((t + d for t, d in spans), default=start)
    topics = [{**t, 'message_count': sum(info['topics_with_message_count'][k]['message_count'] for info in infos)}
              for k, t in enumerate(infos[0]['topics_with_message_count'])]
    return {**infos[-1], 'relative_file_paths': names, 'duration': {'nanoseconds': end - start},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': sum(f['message_count'] for f in files), 'topics_with_message_count': topics,
            'files': files}


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

    def __init__(self, path: str | Path, *, storage: str = 'sqlite3', typestore: Typestore | None = None,
                 layout: Layout = Layout()) -> None:
        """``storage``: 'sqlite3', 'mcap' or 'ros1' (a ROS 1 bag, whose name must end in .bag);
        ``typestore``: the types of what is written, to convert CDR to ROS 1 (default: the event
        types and ROS 2 Jazzy's); ``layout``: a rosbag2's compression and splitting."""
        self.path = Path(path)
        layout.check(self.path)
        self.layout = layout
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
        """A rosbag2's topics by id, of the file being written: what ``write`` writes to."""
        self._issued: dict[int, Connection] = {}
        """A rosbag2's topics by id, as ``add_topic`` gave them: what ``write`` takes."""
        self._parts: _Parts | None = None
        """A split output's files."""
        self.removed_stale: list[Path] = []
        """Partial outputs of killed writers of this destination, removed on entering."""
        self.files: list[str] = []
        """Once written, a rosbag2's storage files, in order."""

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
                self._writer.open()
            elif self.layout.splits:
                self._parts = _Parts(self._tmpdir / 'parts', self.path.name, self.layout)
                self._writer = self._opened(self._parts.next_dir())
            else:
                self._writer = self._opened(self._tmpdir / self.path.name)
        except _WRITE_ERRORS as exc:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            raise BagError(f'{self.path}: cannot open for writing: {exc}') from exc
        except BaseException:  # Ctrl-C, SIGTERM as it opens: __exit__ will not run, so nothing to clean up later
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            raise
        return self

    def _opened(self, where: Path) -> Writer:
        """A rosbags writer of a rosbag2 at ``where``, compressed as the layout says, open."""
        writer = Writer(where, version=9, storage_plugin=STORAGES[self.storage])
        if self.layout.compression is not Compression.NONE:
            writer.set_compression(_ROSBAGS_MODE[self.layout.compression], CompressionFormat.ZSTD)
        writer.open()
        self._batch = _batched(writer)
        return writer

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
        kwargs: dict[str, Any] = {'msgdef': msgdef, 'rihs01': rihs01} if msgdef is not None else {
            'typestore': event_typestore()}
        kwargs.update(serialization_format=serialization_format, offered_qos_profiles=offered_qos_profiles)
        conn = self._writer.add_connection(topic, msgtype, **kwargs)
        if self._parts is not None:
            self._parts.topics.append((topic, msgtype, kwargs))
        self._topics[conn.id] = self._issued[conn.id] = conn
        return conn

    def set_provenance(self, record: Mapping[str, Any]) -> bool:
        """Record ``record`` (JSON) in a rosbag2's metadata, ``custom_data`` key ``evsync``; False for a
        ROS 1 bag, whose format has no place for it."""
        assert self._writer is not None, 'use BagWriter in a with block'
        if isinstance(self._writer, Ros1Writer):
            return False
        self._writer.set_custom_data(PROVENANCE_KEY, json.dumps(record, sort_keys=True))
        if self._parts is not None:
            self._parts.custom[PROVENANCE_KEY] = json.dumps(record, sort_keys=True)
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
            if self._parts is not None and self._issued.get(connection.id) is connection:
                connection = self._split(connection, timestamp, len(raw))
            if self._batch is not None and self._topics.get(connection.id) is connection:
                self._batch.add(connection.id, timestamp, raw)
                self._count(connection.id, timestamp)
            else:  # rosbags' own write: its checks (an unknown connection), its storage
                self._writer.write(connection, timestamp, bytes(raw) if isinstance(raw, bytearray) else raw)
        except _WRITE_ERRORS as exc:
            raise BagError(f'{self.path}: writing failed ({exc}); nothing is left at {self.path}') from exc

    def _split(self, connection: Connection, timestamp: int, nbytes: int) -> Connection:
        """The connection of the file a message goes into: a new file when the layout says it is due
        (``_Parts.due``), given the topics and custom data as the first."""
        parts = self._parts
        assert parts is not None and isinstance(self._writer, Writer)
        if parts.due(timestamp):
            if self._batch is not None:
                self._batch.flush()
            self._writer.close()
            self._writer = self._opened(parts.next_dir())
            self._topics = {}
            for topic, msgtype, kwargs in parts.topics:
                conn = self._writer.add_connection(topic, msgtype, **kwargs)
                self._topics[conn.id] = conn
            for key, value in parts.custom.items():
                self._writer.set_custom_data(key, value)
        parts.add(timestamp, nbytes)
        return self._topics[connection.id]

    @property
    def takes_chunks(self) -> bool:
        """Whether ``write_chunk`` (``write_rows`` when ``takes_rows``) can write: a ROS 1 bag, or an
        uncompressed rosbag2, in one file, whose storage rosbags writes."""
        return self._parts is None and (self._batch is not None or isinstance(self._writer, Ros1Writer))

    @property
    def takes_rows(self) -> bool:
        """Whether the output takes messages as rows (``write_rows``): sqlite3, in one file."""
        return self._parts is None and isinstance(self._batch, _Sqlite3Rows)

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
                self._finish()
                if self.path.exists():
                    raise BagError(f'{self.path}: appeared while writing; refusing to overwrite it')
                (self._tmpdir / self.path.name).rename(self.path)
        finally:
            shutil.rmtree(self._tmpdir, ignore_errors=True)

    def _finish(self) -> None:
        """The output whole in the temporary directory: a split one made of its files; ``files`` said."""
        done = self._tmpdir / self.path.name if self._tmpdir is not None else None
        assert done is not None
        try:
            if self._parts is not None:
                self.files = self._parts.assemble(done)
            elif self.storage != ROS1:
                self.files = sorted(f.name for f in done.iterdir() if f.name != 'metadata.yaml')
        except (OSError, KeyError, ValueError) as exc:
            raise BagError(f'{self.path}: finishing the bag failed ({exc}); nothing is left at {self.path}') from exc
