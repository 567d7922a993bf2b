"""Reading rosbag2 recordings, and ROS 1 bags, with rosbags, including ones rosbags' directory reader
refuses.

A bag directory is read through its ``metadata.yaml`` when rosbags accepts it. Real recorders
also leave bags whose metadata names no storage plugin (``storage_identifier: ''``, as in the
DAVIS346 mcap fixture), and bags with no metadata.yaml at all (a recorder killed before it wrote
one); rosbags refuses those. Such a bag is then read file by file through its storage files, in
name order, their format known from their suffix. Whatever a storage reader raises on a corrupt or
truncated file becomes a ``BagError`` naming the bag. A ``.bag`` file is a ROS 1 bag: its messages
come out as CDR, like a rosbag2's (``bag/ros1.py``). The input is only ever read.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

import apsw
from rosbags.interfaces import Connection
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.reader import DirectoryReader
from rosbags.rosbag2.storage_mcap import McapReader
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader
from rosbags.serde import SerdeError
from rosbags.typesys.store import Typestore
from ruamel.yaml import YAML
from ruamel.yaml.error import YAMLError

from evsync_ros.bag import ros1, sqlitebatches
from evsync_ros.errors import BagError, unreadable
from msg_adapters.errors import MessageError

PROVENANCE_KEY = 'evsync'
"""The key of a restamped rosbag2's ``custom_data`` that says what evsync applied (JSON)."""

_STORAGE_SUFFIXES = ('.mcap', '.db3')
INT64 = (-(1 << 63), 1 << 63)
"""The record times a rosbag2 holds: int64 nanoseconds, [least, end)."""


def all_mcap(storages: list[tuple[McapReader | Sqlite3Reader, dict[int, str]]] | None) -> bool:
    """Whether ``storages`` (``BagReader.storages``) are all mcap files (None: a ROS 1 bag, or messages
    compressed one by one, is not)."""
    return storages is not None and all(isinstance(s, McapReader) for s, _ in storages)


def _storage_files_when_unnamed(bag: Path) -> list[Path] | None:
    """The storage files of a bag whose metadata names no storage plugin, or that has no metadata.yaml
    (lost, or the recorder was killed before writing it); None otherwise."""
    meta = bag / 'metadata.yaml'
    if not meta.is_file():
        files = sorted((f for f in bag.iterdir() if f.suffix in _STORAGE_SUFFIXES), key=_natural)
        if not files:
            raise BagError(f'{bag}: no metadata.yaml and no .mcap or .db3 storage file: not a rosbag2')
        return files
    try:
        info = YAML(typ='safe').load(meta.read_text())['rosbag2_bagfile_information']
        storage_id = info.get('storage_identifier')
        files = [bag / Path(p).name for p in info['relative_file_paths']]
    except (OSError, YAMLError, KeyError, TypeError, AttributeError):
        return None  # malformed metadata: rosbags' own reader reports it precisely
    if storage_id:
        return None
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        raise BagError(f'{bag}: storage files named in metadata.yaml are missing: {missing}')
    return files


def _natural(path: Path) -> tuple[int | str, ...]:
    """Sort key that puts rig_2.mcap before rig_10.mcap (a split recording's order)."""
    return tuple(int(part) if part.isdigit() else part for part in re.split(r'(\d+)', path.name))


def _matched(theirs: Iterable[Connection], ours: Iterable[Connection]) -> dict[int, str]:
    """{id: topic} of a storage file's connections that rosbags' ``DirectoryReader.messages`` matches
    to one of the bag's: the same topic, type and serialization and QoS, and hash where both have one."""
    ours = list(ours)
    return {x.id: x.topic for x in theirs
            if any(y.topic == x.topic and y.msgtype == x.msgtype and y.ext == x.ext
                   and (not x.digest or not y.digest or y.digest == x.digest) for y in ours)}


def _files(reader: Reader) -> list[tuple[Any, dict[int, str]]]:
    """A rosbags reader's storage files, each with the topic of each of its ids that rosbags' reader
    reads (a directory's files: those ``_matched`` to its metadata; a lone file: all of them)."""
    storage = reader.storage
    if isinstance(storage, DirectoryReader):
        return [(s, _matched(s.connections, reader.connections)) for s in storage.storages]
    return [(storage, {c.id: c.topic for c in storage.connections})]


def _listed(storage: McapReader | Sqlite3Reader) -> tuple[dict[int, int], bool]:
    """The messages per id (an mcap channel, a sqlite3 topic) that a storage file's own index lists, and
    whether they are per-id statistics that must add up to the file's count. An mcap file whose
    statistics leave the per-channel map empty ("not available", as the mcap spec allows) is
    counted from its chunk indexes instead, as rosbags counts a file with no statistics."""
    counts = {c.id: c.msgcount for c in storage.connections}
    stats = storage.statistics if isinstance(storage, McapReader) else None
    if stats is None or stats.channel_message_counts or not stats.message_count:
        return counts, True
    assert isinstance(storage, McapReader)  # only an mcap file has statistics
    from_chunks: dict[int, int] = {}
    for chunk in storage.chunks:
        for cid, n in chunk.channel_count.items():
            from_chunks[cid] = from_chunks.get(cid, 0) + n
    return from_chunks, False


def int64_real(value: object) -> bool:
    """Whether ``value`` is a float within int64 nanoseconds (a sqlite3 REAL record time, read as it is)."""
    return type(value) is float and INT64[0] <= value < INT64[1]


class BagReader:
    """Read-only access to a rosbag2 directory or a single .mcap/.db3 file.

    ``connections`` lists one Connection per topic (from the first storage file that has it);
    ``messages()`` yields ``(connection, timestamp_ns, raw_cdr)`` in file order (a ROS 1 bag's in
    file order, converted to CDR).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f'{self.path}: no such bag')
        self.ros1: ros1.StreamingRos1 | None = None
        """The reader of a ROS 1 bag (None: a rosbag2)."""
        self.typestore: Typestore | None = None
        """A ROS 1 bag's types, to convert its messages (None: a rosbag2)."""
        self._readers: list[Reader] = []
        self.connections: list[Connection] = []
        self._pid = os.getpid()
        """The process this reader's files were opened in (``own``)."""
        if self.path.is_file() and ros1.is_ros1(self.path):
            self.ros1 = ros1.StreamingRos1(self.path)
            return
        files = _storage_files_when_unnamed(self.path) if self.path.is_dir() else None
        if files is not None:
            for f in files:
                if f.suffix not in _STORAGE_SUFFIXES:
                    raise BagError(
                        f'{f}: metadata names no storage plugin and the file has no .mcap or .db3 '
                        'suffix to tell its format by'
                    )
            try:
                self._readers = [Reader(f) for f in files]
            except Exception as exc:
                raise unreadable(self.path, exc) from exc
        else:
            try:
                self._readers = [Reader(self.path)]
            except (ReaderError, FileNotFoundError) as exc:
                raise BagError(f'{self.path}: {exc}') from exc
            except Exception as exc:
                raise unreadable(self.path, exc) from exc

    def __enter__(self) -> BagReader:
        self._pid = os.getpid()
        if self.ros1 is not None:
            return self._enter_ros1(self.ros1)
        try:
            for reader in self._readers:
                reader.open()
        except (ReaderError, FileNotFoundError, OSError) as exc:
            self.close()
            raise BagError(f'{self.path}: {exc}') from exc
        except Exception as exc:
            self.close()
            raise unreadable(self.path, exc) from exc
        by_topic: dict[str, Connection] = {}
        for reader in self._readers:
            for conn in reader.connections:
                by_topic.setdefault(conn.topic, conn)
        self.connections = list(by_topic.values())
        unread = self._unread_rows()
        if unread:
            self.close()
            raise BagError(f'{self.path}: {"; ".join(unread)}: rosbags would pass over them unseen')
        return self

    def _unread_rows(self) -> list[str]:
        """What of the storage files no topic of the bag reaches, and reading would silently leave out:
        the messages of a file's topic (a sqlite3 topic, an mcap channel) that its metadata.yaml lists
        otherwise (type, serialization, QoS or hash: rosbags matches them, and reads none of one it
        does not match), and messages whose topic or channel id names none. From the counts rosbags
        makes as it opens a file (an mcap file's from its statistics)."""
        out = []
        for reader in self._readers:
            for s, ids in _files(reader):
                if not isinstance(s, Sqlite3Reader | McapReader):
                    continue
                name = Path(str(s.path)).name
                counts, per_id = _listed(s)
                out += [f'{counts.get(c.id, 0)} messages of {c.topic} in {name}, whose type or QoS there '
                        f'({c.msgtype or "none"}) is not what metadata.yaml says (one of them is corrupt, or the '
                        'file was rewritten under the old metadata.yaml; without it the files are read alone)'
                        for c in s.connections if c.id not in ids and counts.get(c.id, 0)]
                orphans = s.metadata.message_count - sum(counts.values()) if per_id else 0
                if orphans > 0:
                    what = 'channel' if isinstance(s, McapReader) else 'topic'
                    out.append(f'{orphans} messages in {name} whose {what} id names no {what} (a damaged record or '
                               'index, or a layout the readers cannot read)')
        return out

    def _enter_ros1(self, reader: ros1.StreamingRos1) -> BagReader:
        try:
            reader.open()
        except BagError:
            raise
        except Exception as exc:
            raise unreadable(self.path, exc) from exc
        by_topic: dict[str, Connection] = {}
        for conn in reader.connections:
            by_topic.setdefault(conn.topic, conn)
        self.connections = list(by_topic.values())
        try:
            self.typestore = ros1.typestore_for(reader.connections)
        except BagError:
            self.close()
            raise
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def close(self) -> None:
        """Close every storage reader (a reader of a corrupt file that fails to close is let go)."""
        for reader in self._readers:
            if reader.is_open:
                with contextlib.suppress(Exception):  # closing a reader of a corrupt file: nothing to save
                    reader.close()

    @property
    def span_ns(self) -> int:
        """From the first message's record timestamp to the last's, over every storage file (0: none)."""
        if self.ros1 is not None:
            return self.ros1.end_time - self.ros1.start_time if self.ros1.message_count else 0
        spans = [(r.start_time, r.end_time) for r in self._readers if r.message_count]
        if not spans:
            return 0
        return max(e for _, e in spans) - min(s for s, _ in spans)

    @property
    def provenance(self) -> dict[str, Any] | None:
        """What evsync applied to make this bag (``BagWriter.set_provenance``): a rosbag2's
        ``custom_data`` key ``evsync``, read back; None when there is none (or a ROS 1 bag)."""
        meta = self.path / 'metadata.yaml'
        if self.ros1 is not None or not meta.is_file():
            return None
        try:
            info = YAML(typ='safe').load(meta.read_text())['rosbag2_bagfile_information']
            text = (info.get('custom_data') or {}).get(PROVENANCE_KEY)
        except (OSError, YAMLError, KeyError, TypeError, AttributeError) as exc:
            raise BagError(f'{meta}: cannot read its custom_data ({exc})') from exc
        if text is None:
            return None
        try:
            record = json.loads(text)
        except (ValueError, TypeError) as exc:
            raise BagError(f'{self.path}: its evsync provenance is not JSON ({exc})') from exc
        return record if isinstance(record, dict) else None

    @property
    def start_ns(self) -> int:
        """The first message's record timestamp, over every storage file (0: none)."""
        if self.ros1 is not None:
            return self.ros1.start_time if self.ros1.message_count else 0
        starts = [r.start_time for r in self._readers if r.message_count]
        return min(starts) if starts else 0

    @contextlib.contextmanager
    def own(self) -> Iterator[BagReader]:
        """This bag, open for reading in the calling process: itself in the process that opened it, or
        where a forked process may read its open files (a ROS 1 bag, mcap files read a chunk at a
        time at their offsets); else, in a forked process (``pipeline``), the bag opened again there,
        closed on leaving (a sqlite3 connection must not cross a fork)."""
        if self._pid == os.getpid() or self._shared_after_fork():
            yield self
            return
        with BagReader(self.path) as again:
            yield again

    @contextlib.contextmanager
    def rows(self, storage: Sqlite3Reader) -> Iterator[apsw.Connection]:
        """A connection to ``storage`` (a sqlite3 file of ``storages()``) that the calling process may
        read: its own in the process that opened the bag; in a forked process, one opened there
        (``sqlitebatches.connect``), closed on leaving. The file alone is opened again, not the whole
        bag as ``own`` does: rosbags' opening of a bag counts every row of it. (A file rosbags
        decompressed on opening the bag is its decompressed copy, read as it is.)"""
        if self._pid == os.getpid():
            assert storage.dbconn is not None  # the bag is open
            yield storage.dbconn
            return
        assert isinstance(storage.path, Path)  # rosbags reads a remote path only when given one
        try:
            conn = sqlitebatches.connect(storage.path)
        except Exception as exc:  # apsw's errors, whatever their class
            raise BagError(f'{self.path}: cannot open {storage.path} again ({exc})') from exc
        try:
            yield conn
        finally:
            conn.close()

    def _shared_after_fork(self) -> bool:
        return self.ros1 is not None or all_mcap(self.storages())

    def window_ns(self, start_s: float | None, duration_s: float | None) -> tuple[int, int] | None:
        """``start_s`` and ``duration_s`` (seconds from the bag's first message) as record times
        [start, stop); None when neither is given. BagError when the stretch is not in the bag."""
        if start_s is None and duration_s is None:
            return None
        start_s = start_s or 0.0
        span_s = self.span_ns / 1e9
        if start_s < 0 or (duration_s is not None and duration_s <= 0):
            raise BagError(f'{self.path}: --start must be >= 0 and --duration > 0 seconds, '
                           f'got start {start_s:g}, duration {duration_s}')
        if start_s >= span_s:
            raise BagError(f'{self.path}: --start {start_s:g} s is past the bag\'s end ({span_s:.3f} s of messages)')
        start = self.start_ns + round(start_s * 1e9)
        stop = start + round(duration_s * 1e9) if duration_s is not None else self.start_ns + self.span_ns + 1
        return start, stop

    def message_counts(self) -> dict[str, int]:
        """Messages per topic, from the storage indexes."""
        counts: dict[str, int] = {}
        for reader in [self.ros1] if self.ros1 is not None else self._readers:
            for conn in reader.connections:
                counts[conn.topic] = counts.get(conn.topic, 0) + conn.msgcount
        return counts

    def listed(self) -> dict[str, int]:
        """Messages per topic that the storage files' own indexes list, of those ``messages`` reads (an
        mcap file's statistics or chunk indexes, a sqlite3 file's rows, a ROS 1 bag's chunk infos;
        not metadata.yaml's): what a whole read yields (``unread``)."""
        if self.ros1 is not None:
            pairs = [(c.topic, c.msgcount) for c in self.ros1.connections]
        else:
            files = [(_listed(s)[0], ids) for reader in self._readers for s, ids in _files(reader)]
            pairs = [(topic, counts.get(cid, 0)) for counts, ids in files for cid, topic in ids.items()]
        counts: dict[str, int] = {}
        for topic, n in pairs:
            counts[topic] = counts.get(topic, 0) + n
        return counts

    def unread(self, read: Mapping[str, int]) -> BagError | None:
        """The error of a whole read of ``read``'s topics ({topic: messages read}) that read fewer of a
        topic's messages than its index lists (``listed``): records the readers, rosbags' too, pass
        over (a channel or connection id that names none, a time outside its chunk's, a damaged
        index or record, a layout they cannot read), whose messages would otherwise be lost unseen.
        None when none is missing."""
        listed = self.listed()
        short = [f'{listed[t] - n} of the {listed[t]} of {t}' for t, n in sorted(read.items()) if listed.get(t, 0) > n]
        if not short:
            return None
        return BagError(f'{self.path}: messages its index lists could not be read: {", ".join(short)} (records '
                        'the readers pass over: a damaged record or index, or a layout they cannot read)')

    def check_whole(self, read: Mapping[str, int]) -> None:
        """``unread``, raised."""
        error = self.unread(read)
        if error is not None:
            raise error

    def storages(self) -> list[tuple[McapReader | Sqlite3Reader, dict[int, str]]] | None:
        """The open storage files that ``messages`` reads, in its order, each with the topic of each
        of its channels or topic ids whose messages ``messages`` yields (rosbags matches a file's to
        the bag's by topic, type, serialization and QoS, and hash); None for a ROS 1 bag or a bag
        whose messages are compressed one by one."""
        if self.ros1 is not None:
            return None
        out: list[tuple[McapReader | Sqlite3Reader, dict[int, str]]] = []
        for reader in self._readers:
            storage = reader.storage
            if isinstance(storage, DirectoryReader) and storage.metadata.compression_mode == 'message':
                return None
            inner = _files(reader)
            if not all(isinstance(s, McapReader | Sqlite3Reader) for s, _ in inner):
                return None
            out += [(s, ids) for s, ids in inner if isinstance(s, McapReader | Sqlite3Reader)]
        return out

    def messages(self, topics: Iterable[str] | None = None, *, native: bool = False,
                 window: tuple[int, int] | None = None) -> Iterator[tuple[Connection, int, bytes]]:
        """Yield ``(connection, timestamp_ns, raw_cdr)`` in file order; only ``topics`` when given;
        ``native``: a ROS 1 bag's messages as its own (ROS 1) bytes, not converted. A ROS 1 message
        that does not match its definition comes as ``ros1.Unconverted`` (its bytes and why), for
        the caller to count. ``window`` (from ``window_ns``): only messages recorded in [start, stop).

        Raises:
            BagError: a storage file turns out corrupt or truncated while it is read.
        """
        wanted = None if topics is None else set(topics)
        if self.ros1 is not None:
            messages = self._ros1_messages(self.ros1, wanted, native=native)
            if window is None:
                yield from messages
            else:
                yield from (m for m in messages if window[0] <= m[1] < window[1])
            return
        start, stop = window if window is not None else (None, None)
        for reader in self._readers:
            conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
            if not conns:
                continue
            try:
                for conn, timestamp, data in reader.messages(connections=conns, start=start, stop=stop):
                    if type(data) is not bytes or (type(timestamp) is not int and not int64_real(timestamp)):
                        raise self.bad_row(conn.topic, timestamp, data)
                    yield conn, timestamp, data
            except BagError:
                raise
            except ReaderError as exc:
                raise BagError(f'{self.path}: {exc}') from exc
            except Exception as exc:
                raise unreadable(self.path, exc) from exc

    def bad_row(self, topic: str, timestamp: object, data: object) -> BagError:
        """The error of a crafted sqlite3 row of ``topic`` that ``messages`` cannot yield (rosbags' reader
        gives it as it is stored): its data not a BLOB, or its record time not a number of
        nanoseconds in int64 (TEXT, BLOB, NULL, a REAL beyond it)."""
        if type(data) is not bytes:
            return BagError(f'{self.path}: a message of {topic} is stored as {type(data).__name__}, not bytes; '
                            'the storage file is corrupt')
        return BagError(f'{self.path}: a message of {topic} has the record time {timestamp!r}, not a number of '
                        'nanoseconds in int64; the storage file is corrupt')

    def converted(self, raw: bytes, msgtype: str) -> bytes:
        """A ROS 1 bag's message of ``msgtype`` (its own bytes) as ``messages`` yields it: as CDR, or
        ``ros1.Unconverted`` (its bytes and why) when it does not match its definition."""
        store = self.typestore
        assert store is not None, 'a ROS 1 bag'
        try:
            return ros1.to_cdr(store, raw, msgtype)
        except (SerdeError, MessageError) as exc:
            bad = ros1.Unconverted(raw)
            bad.error = f'does not match its definition of {msgtype} ({exc})'
            return bad

    def _ros1_messages(self, reader: ros1.StreamingRos1, wanted: set[str] | None, *, native: bool
                       ) -> Iterator[tuple[Connection, int, bytes]]:
        conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
        if not conns:
            return
        try:
            for conn, stamp, raw in reader.messages(conns):
                yield conn, stamp, raw if native else self.converted(raw, conn.msgtype)
        except BagError:
            raise
        except Exception as exc:
            raise unreadable(self.path, exc) from exc
