"""A sqlite3 bag restamped a batch of rows at a time (``restamp._copy_chunks``, ``sqlitebatches``),
into sqlite3 or into mcap, and an mcap bag into sqlite3, give what restamping message by message
gives: the same messages, bytes, record times and order and the same report, with malformed
messages among real ones, under the cases of ``chunkcopies``; and a database that cannot be read
is a BagError naming the bag."""

from __future__ import annotations

import pytest
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

from evsync_ros.bag import sqlitebatches
from evsync_ros.bag.reader import BagReader
from evsync_ros.errors import BagError
from evsync_testing.chunkcopies import ARRAYS, CASES, EVT3, both_ways, mixed_rows, write_mixed
from evsync_testing.digest import bag_digest

PAIRS = [('sqlite3', 'sqlite3'), ('sqlite3', 'mcap'), ('mcap', 'sqlite3')]


@pytest.fixture(scope='module')
def mixed(real_data, tmp_path_factory):
    rows = mixed_rows(real_data)
    folder = tmp_path_factory.mktemp('mixed3')
    return {(storage, late): write_mixed(folder / f'{storage}{late}', rows, late=late, storage=storage)
            for storage in ('sqlite3', 'mcap') for late in (False, True)}


@pytest.mark.parametrize(('src', 'dst'), PAIRS)
@pytest.mark.parametrize('case', list(CASES))
def test_batch_by_batch_is_message_by_message(mixed, tmp_path, monkeypatch, case, src, dst, small_batches):
    kwargs = {'reference': EVT3, **CASES[case]}
    bag = mixed[src, case == 'record times moved out of range']
    fast, slow, chunks, messages = both_ways(bag, tmp_path, monkeypatch, storage=dst, **kwargs)
    assert fast.topics == slow.topics
    assert bag_digest(chunks) == bag_digest(messages)
    assert fast.topics[EVT3].unchanged_bad > 0 and fast.topics[ARRAYS].restamped > 0


@pytest.fixture
def small_batches(monkeypatch):
    """Batches of 100 rows, so that a stream's state crosses batches many times."""
    monkeypatch.setattr(sqlitebatches, 'BATCH_ROWS', 100)
    batches = sqlitebatches.batches
    monkeypatch.setattr(sqlitebatches, 'batches', lambda storage, ids, *, name, size=100: batches(
        storage, ids, name=name, size=size))


@pytest.mark.parametrize('fraction', [0.3, 0.6, 0.9])
def test_a_cut_database_is_a_bag_error_naming_it(mixed, tmp_path, fraction):
    """Cut short, as a full disk or a killed copy leaves it: refused when opened or when read."""
    src = mixed['sqlite3', False]
    broken = tmp_path / 'broken'
    broken.mkdir()
    for f in src.iterdir():
        data = f.read_bytes()
        (broken / f.name).write_bytes(data[:int(len(data) * fraction)] if f.suffix == '.db3' else data)
    with pytest.raises(BagError, match='broken'), BagReader(broken) as reader:
        for storage, ids in reader.storages() or []:
            assert isinstance(storage, Sqlite3Reader)
            for _ in sqlitebatches.batches(storage, ids, name=str(broken)):
                pass
