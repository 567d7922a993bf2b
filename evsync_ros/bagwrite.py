"""Writing rosbag2 recordings with rosbags, so that a partial output never looks complete.

``BagWriter`` writes into a hidden temporary directory beside the destination and renames it into
place only when the ``with`` block ends without an exception; on any failure the temporary
directory is removed. An existing destination is never overwritten.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from types import TracebackType

from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.errors import WriterError

from msg_adapters.definitions import event_typestore

from .errors import BagError

STORAGES = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}


class BagWriter:
    """``with BagWriter(path, storage='mcap') as w: c = w.add_topic(...); w.write(c, t, raw)``."""

    def __init__(self, path: str | Path, *, storage: str = 'sqlite3') -> None:
        self.path = Path(path)
        if storage not in STORAGES:
            raise BagError(f'{self.path}: storage must be one of {", ".join(STORAGES)}, got {storage!r}')
        if self.path.exists():
            raise BagError(f'{self.path}: exists already; refusing to overwrite it')
        if not self.path.parent.is_dir():
            raise BagError(f'{self.path}: parent directory {self.path.parent} does not exist')
        self.storage = storage
        self._tmpdir: Path | None = None
        self._writer: Writer | None = None

    def __enter__(self) -> BagWriter:
        self._tmpdir = Path(tempfile.mkdtemp(prefix=f'.{self.path.name}.', suffix='.partial', dir=self.path.parent))
        try:
            self._writer = Writer(self._tmpdir / self.path.name, version=9, storage_plugin=STORAGES[self.storage])
            self._writer.open()
        except (WriterError, OSError) as exc:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            raise BagError(f'{self.path}: cannot open for writing: {exc}') from exc
        return self

    def add_topic(self, topic: str, msgtype: str, *, msgdef: str | None = None, rihs01: str | None = None,
                  serialization_format: str = 'cdr', offered_qos_profiles=()) -> Connection:
        assert self._writer is not None, 'use BagWriter in a with block'
        kwargs = {'msgdef': msgdef, 'rihs01': rihs01} if msgdef is not None else {'typestore': event_typestore()}
        return self._writer.add_connection(topic, msgtype, serialization_format=serialization_format,
                                           offered_qos_profiles=offered_qos_profiles, **kwargs)

    def write(self, connection: Connection, timestamp_ns: int, raw: bytes | bytearray | memoryview) -> None:
        assert self._writer is not None, 'use BagWriter in a with block'
        self._writer.write(connection, int(timestamp_ns), bytes(raw) if isinstance(raw, bytearray) else raw)

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        assert self._writer is not None and self._tmpdir is not None
        try:
            self._writer.close()
            if exc_type is None:
                if self.path.exists():
                    raise BagError(f'{self.path}: appeared while writing; refusing to overwrite it')
                os.rename(self._tmpdir / self.path.name, self.path)
        finally:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
