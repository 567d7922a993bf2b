"""Writing rosbag2 recordings, and ROS 1 bags, with rosbags, so that a partial output never looks
complete.

``BagWriter`` writes into a hidden temporary directory beside the destination,
``.NAME.PID.XXXX.partial``, and renames it into place only when the ``with`` block ends without an
exception; on any failure the temporary directory is removed, and a failure to write (a full disk,
a file size limit) is a ``BagError`` naming the destination. A process killed outright (SIGKILL, a
power cut) cannot clean up: its partial directory stays hidden, never at the destination, and the
next ``BagWriter`` for the same destination removes it once its process is gone. An existing
destination is never overwritten. Storage ``ros1`` writes a ROS 1 bag (one ``.bag`` file, renamed
into place the same way); ``write`` takes CDR and converts it, ``write_ros1`` takes ROS 1 bytes.
"""

from __future__ import annotations

import glob
import json
import os
import shutil
import sqlite3
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

from rosbags.interfaces import Connection, Qos
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag1 import WriterError as Ros1WriterError
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.errors import WriterError
from rosbags.serde import SerdeError
from rosbags.typesys.store import Typestore

from evsync_ros.bag import ros1
from evsync_ros.bag.reader import PROVENANCE_KEY
from evsync_ros.errors import BagError
from msg_adapters.definitions import event_typestore
from msg_adapters.errors import MessageError

STORAGES = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}
"""The rosbag2 storages."""
ROS1 = 'ros1'
"""The storage of a ROS 1 bag."""
_WRITE_ERRORS = (WriterError, Ros1WriterError, OSError, sqlite3.Error)


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
        self.typestore = typestore if typestore is not None else event_typestore()
        self._tmpdir: Path | None = None
        self._writer: Writer | Ros1Writer | None = None
        self.removed_stale: list[Path] = []
        """Partial outputs of killed writers of this destination, removed on entering."""

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
        except _WRITE_ERRORS as exc:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            raise BagError(f'{self.path}: cannot open for writing: {exc}') from exc
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
        return self._writer.add_connection(topic, msgtype, serialization_format=serialization_format,
                                           offered_qos_profiles=offered_qos_profiles, **kwargs)

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
        try:
            self._writer.write(connection, int(timestamp_ns), bytes(raw) if isinstance(raw, bytearray) else raw)
        except _WRITE_ERRORS as exc:
            raise BagError(f'{self.path}: writing failed ({exc}); nothing is left at {self.path}') from exc

    def write_ros1(self, connection: Connection, timestamp_ns: int, raw: bytes | memoryview) -> None:
        """Write one message of a ROS 1 bag, given as its ROS 1 bytes."""
        assert isinstance(self._writer, Ros1Writer), 'write_ros1 writes a ROS 1 bag only'
        try:
            self._writer.write(connection, int(timestamp_ns), raw)
        except _WRITE_ERRORS as exc:
            raise BagError(f'{self.path}: writing failed ({exc}); nothing is left at {self.path}') from exc

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        assert self._writer is not None and self._tmpdir is not None
        try:
            try:
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
