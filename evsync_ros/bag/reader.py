"""Reading a bag, the one way in for every command: a rosbag2 directory, a single .mcap/.db3 file, or a
ROS 1 ``.bag``, opened with rosbags and read through a plugin per storage (``PLUGINS``, as rosbags
keys its ``STORAGE_PLUGINS``). How each storage is read, and when rosbags' reader reads instead:
docs/bags.md, "Reading a bag". The input is only ever read."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from types import TracebackType
from typing import Any, Protocol, TypeVar

from rosbags.interfaces import Connection
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.errors import ReaderError
from rosbags.typesys.store import Typestore

from evsync_ros.bag import files, pipeline, ros1
from evsync_ros.bag.files import Part
from evsync_ros.bag.records import Chunk
from evsync_ros.bag.storage import Storage
from evsync_ros.bag.storage_mcap import McapPlugin
from evsync_ros.bag.storage_ros1 import Ros1Plugin, StreamingRos1
from evsync_ros.bag.storage_sqlite3 import Sqlite3Plugin, bad_row
from evsync_ros.errors import BagError, unreadable

__all__ = ['PLUGINS', 'BagReader', 'Message', 'Plugin']

T = TypeVar('T')
Message = tuple[Connection, int, bytes]
"""(connection, record time in ns, the message's bytes: CDR, or a ROS 1 bag's own with ``native``)."""


class Plugin(Protocol):
    """How a storage's files are read (``PLUGINS``); a part is one storage file of the bag (``Part``)."""

    def messages(self, part: Part, *, window: tuple[int, int] | None, native: bool) -> Iterator[Message]:
        """The part's messages of its connections, in rosbags' reader's order (recorded in ``window``)."""

    def chunks(self, part: Part) -> Iterator[Chunk] | None:
        """The part's chunks in that order, each with its rows of the part's connections, as the storage
        holds them (``records``); None where its chunks cannot give that order (asked here, in the
        process that opened the bag; the chunks are read where the iterator runs)."""


PLUGINS: Mapping[Storage, Plugin] = {Storage.SQLITE3: Sqlite3Plugin(), Storage.MCAP: McapPlugin(),
                                     Storage.ROS1: Ros1Plugin()}
"""Each storage's reads."""


class BagReader:
    """Read-only access to a bag: ``with BagReader(path) as reader: reader.messages(...)``.

    ``connections`` lists one Connection per topic (from the first storage file that has it);
    ``messages()`` yields ``(connection, timestamp_ns, raw)`` in rosbags' order (a ROS 1 bag's in file
    order, converted to CDR); ``chunks()`` gives the storage's own chunks, for a copy a chunk at a
    time; ``deliver()`` makes blocks of what is read in a second process; ``check_whole()`` says
    what a whole read passed over.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f'{self.path}: no such bag')
        self.typestore: Typestore | None = None
        """A ROS 1 bag's types, to convert its messages (None: a rosbag2)."""
        self.connections: list[Connection] = []
        self._ros1: StreamingRos1 | None = None
        self._readers: list[Reader] = []
        self._pid = os.getpid()
        """The process this reader's files were opened in (``parts``)."""
        if self.path.is_file() and ros1.is_ros1(self.path):
            self._ros1 = StreamingRos1(self.path)
            return
        unnamed = files.storage_files(self.path) if self.path.is_dir() else None
        try:
            self._readers = [Reader(f) for f in unnamed] if unnamed is not None else [Reader(self.path)]
        except (ReaderError, FileNotFoundError) as exc:
            if unnamed is not None:
                raise unreadable(self.path, exc) from exc
            raise BagError(f'{self.path}: {exc}') from exc
        except Exception as exc:
            raise unreadable(self.path, exc) from exc

    def __enter__(self) -> BagReader:
        self._pid = os.getpid()
        if self._ros1 is not None:
            return self._enter_ros1(self._ros1)
        try:
            for reader in self._readers:
                reader.open()
        except ReaderError as exc:  # a storage file that is there and does not open as one: cut short, or corrupt
            self.close()
            raise unreadable(self.path, exc) from exc
        except (FileNotFoundError, OSError) as exc:
            self.close()
            raise BagError(f'{self.path}: {exc}') from exc
        except Exception as exc:
            self.close()
            raise unreadable(self.path, exc) from exc
        self.connections = _first_per_topic(c for reader in self._readers for c in reader.connections)
        unread = files.unread_rows(self._readers)
        if unread:
            self.close()
            raise BagError(f'{self.path}: {"; ".join(unread)}: rosbags would pass over them unseen')
        return self

    def _enter_ros1(self, bag: StreamingRos1) -> BagReader:
        try:
            bag.open()
        except BagError:
            raise
        except Exception as exc:
            raise unreadable(self.path, exc) from exc
        self.connections = _first_per_topic(bag.connections)
        self.typestore = ros1.typestore_for(bag.connections)
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
    def storage(self) -> Storage:
        """The bag's storage (a rosbag2 of several files: its first file's)."""
        return Storage.ROS1 if self._ros1 is not None else files.storage_of(self._readers, self.path)

    @property
    def span_ns(self) -> int:
        """From the first message's record timestamp to the last's, over every storage file (0: none)."""
        if self._ros1 is not None:
            return self._ros1.end_time - self._ros1.start_time if self._ros1.message_count else 0
        spans = [(r.start_time, r.end_time) for r in self._readers if r.message_count]
        if not spans:
            return 0
        return max(e for _, e in spans) - min(s for s, _ in spans)

    @property
    def start_ns(self) -> int:
        """The first message's record timestamp, over every storage file (0: none)."""
        if self._ros1 is not None:
            return self._ros1.start_time if self._ros1.message_count else 0
        starts = [r.start_time for r in self._readers if r.message_count]
        return min(starts) if starts else 0

    @property
    def provenance(self) -> dict[str, Any] | None:
        """What evsync applied to make this bag (``BagWriter.set_provenance``): a rosbag2's
        ``custom_data`` key ``evsync``, read back; None when there is none (or a ROS 1 bag)."""
        return files.provenance(self.path) if self._ros1 is None else None

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
        for reader in [self._ros1] if self._ros1 is not None else self._readers:
            for conn in reader.connections:
                counts[conn.topic] = counts.get(conn.topic, 0) + conn.msgcount
        return counts

    def listed(self) -> dict[str, int]:
        """Messages per topic that the storage files' own indexes list, of those ``messages`` reads (an
        mcap file's statistics or chunk indexes, a sqlite3 file's rows, a ROS 1 bag's chunk infos;
        not metadata.yaml's): what a whole read yields (``unread``)."""
        if self._ros1 is not None:
            pairs = [(c.topic, c.msgcount) for c in self._ros1.connections]
        else:
            pairs = files.listed_topics(self._readers)
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

    def parts(self, topics: Iterable[str] | None = None) -> list[Part] | None:
        """The storage files a read of ``topics`` (default: all) goes through, in its order, each with its
        connections of them (files with none left out); a ROS 1 bag is one. None for a bag whose
        messages are compressed one by one, which rosbags' reader reads whole."""
        wanted = None if topics is None else set(topics)
        if self._ros1 is not None:
            whole = [Part(Storage.ROS1, self.path, self._ros1, {c.id: c for c in self._ros1.connections},
                          self._pid, self.typestore)]
        else:
            found = files.parts_of(self._readers, path=self.path, pid=self._pid)
            if found is None:
                return None
            whole = found
        if wanted is None:
            return [p for p in whole if p.conns]
        mine = [(p, {i: c for i, c in p.conns.items() if c.topic in wanted}) for p in whole]
        return [Part(p.storage, p.path, p.file, conns, p.pid, p.typestore) for p, conns in mine if conns]

    def messages(self, topics: Iterable[str] | None = None, *, native: bool = False,
                 window: tuple[int, int] | None = None) -> Iterator[Message]:
        """Yield ``(connection, timestamp_ns, raw)`` in rosbags' reader's order (a ROS 1 bag's in file
        order), through each storage's plugin; only ``topics`` when given; ``native``: a ROS 1 bag's
        messages as its own (ROS 1) bytes, not converted. A ROS 1 message that does not match its
        definition comes as ``ros1.Unconverted`` (its bytes and why), for the caller to count.
        ``window`` (from ``window_ns``): only messages recorded in [start, stop). A forked process
        (``deliver``) may read too.

        Raises:
            BagError: a storage file turns out corrupt or truncated while it is read (whatever its
                reader raised, naming the bag).
        """
        parts = self.parts(topics)
        try:
            if parts is None:
                yield from self._whole(topics, window)
            for part in parts or ():
                yield from PLUGINS[part.storage].messages(part, window=window, native=native)
        except BagError:
            raise
        except ReaderError as exc:
            raise BagError(f'{self.path}: {exc}') from exc
        except Exception as exc:
            raise unreadable(self.path, exc) from exc

    def _whole(self, topics: Iterable[str] | None, window: tuple[int, int] | None) -> Iterator[Message]:
        """``messages`` through rosbags' reader of the whole bag (in a forked process, of the bag opened
        again there: ``reopened``), each row checked as a sqlite3 plugin checks it."""
        wanted = None if topics is None else set(topics)
        start, stop = window if window is not None else (None, None)
        with self.reopened() as bag:
            for reader in bag._readers:
                conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
                if not conns:
                    continue
                for conn, timestamp, data in reader.messages(connections=conns, start=start, stop=stop):
                    if type(data) is not bytes or type(timestamp) is not int:
                        error = bad_row(self.path, conn.topic, timestamp, data)
                        if error is not None:
                            raise error
                    yield conn, timestamp, data

    @contextlib.contextmanager
    def reopened(self) -> Iterator[BagReader]:
        """This bag, open for rosbags' reader of it in the calling process: itself in the process that
        opened it; in a forked process (``deliver``), the bag opened again there, closed on leaving (a
        sqlite3 connection must not cross a fork)."""
        if self._pid == os.getpid():
            yield self
            return
        with BagReader(self.path) as again:
            yield again

    def chunks(self, types: Mapping[str, str]) -> Iterator[tuple[Chunk, dict[int, str]]] | None:
        """The chunks of the storage files that hold ``types``' topics ({topic: message type}), in
        ``messages``' order, each with the topic of each id its rows carry (the rows of those topics
        alone), as the storage holds them: a rosbag2's CDR (sqlite3 files a batch of rows at a time),
        a ROS 1 bag's own bytes. None where the chunks cannot give that order (``Plugin.chunks``), for
        a bag whose messages are compressed one by one, or a rosbag2 file whose type of a topic is not
        ``types``'."""
        parts = self.parts(types)
        if parts is None or (self._ros1 is None and any(types[c.topic] != c.msgtype for p in parts
                                                         for c in p.conns.values())):
            return None
        made = [(PLUGINS[p.storage].chunks(p), {i: c.topic for i, c in p.conns.items()}) for p in parts]
        if any(chunks is None for chunks, _ in made):
            return None
        return ((chunk, topic_of) for chunks, topic_of in made for chunk in chunks or ())

    def deliver(self, blocks: Iterator[pipeline.Block], use: pipeline.Use, *, result: Callable[[], T],
                forked: bool) -> T:
        """Each of ``blocks`` (made from what is read of this bag) made and used in order (``pipeline``):
        in this process, or ``forked``, made in a forked process while this one uses each as it
        arrives, where the reads go through what that process may read (a sqlite3 file through a
        connection of its own, ``storage_sqlite3.connection``). Returns ``result()`` as the making
        process has it once ``blocks`` ends (what the making changed, which this process never sees).

        Raises:
            what ``blocks`` or ``use`` raised, or BagError when the forked process ends unfinished.
        """
        if forked:
            return pipeline.pipelined(blocks, use, result=result, name=str(self.path))
        pipeline.serial(blocks, use)
        return result()

    def converted(self, raw: bytes, msgtype: str) -> bytes:
        """A ROS 1 bag's message of ``msgtype`` (its own bytes) as ``messages`` yields it: as CDR, or
        ``ros1.Unconverted`` (its bytes and why) when it does not match its definition."""
        assert self.typestore is not None, 'a ROS 1 bag'
        return ros1.converted(self.typestore, raw, msgtype)


def _first_per_topic(conns: Iterable[Connection]) -> list[Connection]:
    """The first connection of each topic, in order."""
    by_topic: dict[str, Connection] = {}
    for conn in conns:
        by_topic.setdefault(conn.topic, conn)
    return list(by_topic.values())
