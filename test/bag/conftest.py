"""Fixtures of the bag front end's tests."""

from __future__ import annotations

import os

import pytest
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

from evsync_ros.bag import pipeline, sqlitebatches


@pytest.fixture
def own_connections(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every read of a sqlite3 file goes through a connection opened in the process that reads (a
    connection that crossed a fork fails the read, and so the test)."""
    opened = Sqlite3Reader.open

    def open_here(self: Sqlite3Reader) -> None:
        opened(self)
        self.opened_in = os.getpid()  # type: ignore[attr-defined]

    def here(storage: Sqlite3Reader) -> Sqlite3Reader:
        if storage.opened_in != os.getpid():  # type: ignore[attr-defined]
            raise RuntimeError('a sqlite3 connection crossed a fork')
        return storage

    batches, messages = sqlitebatches.batches, Sqlite3Reader.messages
    monkeypatch.setattr(Sqlite3Reader, 'open', open_here)
    monkeypatch.setattr(sqlitebatches, 'batches', lambda s, *a, **k: batches(here(s), *a, **k))
    monkeypatch.setattr(Sqlite3Reader, 'messages', lambda s, *a, **k: messages(here(s), *a, **k))


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
