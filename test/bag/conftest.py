"""Fixtures of the bag front end's tests."""

from __future__ import annotations

import os
import tempfile
from typing import Any

import pytest
from rosbags.rosbag2 import reader as rosbag2_reader
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

from evsync_ros.bag import pipeline, storage_sqlite3


@pytest.fixture
def own_connections(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every read of a sqlite3 file goes through a connection opened in the process that reads (a
    connection that crossed a fork fails the read, and so the test)."""
    opened_in: dict[int, tuple[object, int]] = {}  # id of a connection: (it, kept alive; the process that opened it)
    opened, connect = Sqlite3Reader.open, storage_sqlite3.connect

    def open_here(self: Sqlite3Reader) -> None:
        opened(self)
        opened_in[id(self.dbconn)] = (self.dbconn, os.getpid())

    def connect_here(path: object) -> object:
        conn = connect(path)  # type: ignore[arg-type]
        opened_in[id(conn)] = (conn, os.getpid())
        return conn

    def here(conn: Any) -> Any:
        if opened_in[id(conn)][1] != os.getpid():
            raise RuntimeError('a sqlite3 connection crossed a fork')
        return conn

    batches, rows, messages = storage_sqlite3.batches, storage_sqlite3.messages, Sqlite3Reader.messages

    def messages_here(storage: Sqlite3Reader, *args: object, **kwargs: object) -> object:
        here(storage.dbconn)
        return messages(storage, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(Sqlite3Reader, 'open', open_here)
    monkeypatch.setattr(storage_sqlite3, 'connect', connect_here)
    monkeypatch.setattr(storage_sqlite3, 'batches', lambda c, *a, **k: batches(here(c), *a, **k))
    monkeypatch.setattr(storage_sqlite3, 'messages', lambda c, *a, **k: rows(here(c), *a, **k))
    monkeypatch.setattr(Sqlite3Reader, 'messages', messages_here)


@pytest.fixture
def forks(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """One entry per pipeline started (``pipeline.pipelined``, each run as it would be)."""
    started: list[int] = []
    real = pipeline.pipelined

    def counted(*args: object, **kwargs: object) -> object:
        started.append(1)
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(pipeline, 'pipelined', counted)
    return started


@pytest.fixture
def decompressions(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """One entry per temporary directory rosbags' reader makes: a bag compressed file by file is
    decompressed whole into one as it opens."""
    made: list[int] = []
    real = tempfile.TemporaryDirectory

    def counted(*args: Any, **kwargs: Any) -> Any:
        made.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(rosbag2_reader, 'TemporaryDirectory', counted)
    return made
