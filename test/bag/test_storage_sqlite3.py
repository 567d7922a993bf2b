"""A sqlite3 bag restamped a batch of rows at a time (``restamp._copy_chunks``, ``storage_sqlite3``),
into sqlite3 or into mcap, and an mcap bag into sqlite3, give what restamping message by message
gives: the same messages, bytes, record times and order and the same report, with malformed
messages among real ones, under the cases of ``chunkcopies``; and a database that cannot be read
is a BagError naming the bag."""

from __future__ import annotations

import sqlite3

import pytest
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

from evsync_ros.bag import storage_sqlite3
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.writer import BagWriter
from evsync_ros.errors import BagError
from evsync_testing.chunkcopies import ARRAYS, CASES, EVT3, both_ways, mixed_rows, write_mixed
from evsync_testing.crafted import STRING, two_topics
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
    monkeypatch.setattr(storage_sqlite3, 'BATCH_ROWS', 100)
    batches = storage_sqlite3.batches
    monkeypatch.setattr(storage_sqlite3, 'batches', lambda conn, ids, *, name, size=100: batches(
        conn, ids, name=name, size=size))


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
        for part in reader.parts() or []:
            assert isinstance(part.file, Sqlite3Reader)
            for _ in storage_sqlite3.batches(part.file.dbconn, part.conns, name=str(broken)):
                pass


@pytest.mark.parametrize('index', [True, False])
def test_integer_times_asks_of_the_topics_given(tmp_path, index):
    """Record times that are not integers on one topic only: the other topic's are all integers (its
    rows can be read in batches), whether sqlite answers the question of every row from the
    timestamp index or from the rows."""
    bag = tmp_path / 'bag'
    a, b = two_topics(bag, storage='sqlite3')
    db = sqlite3.connect(next(bag.glob('*.db3')))
    with db:
        db.execute('UPDATE messages SET timestamp=timestamp+0.5 WHERE topic_id=? AND timestamp=21', (b.id,))
        if not index:
            db.execute('DROP INDEX timestamp_idx')
    db.close()
    with BagReader(bag) as reader:
        (part,) = reader.parts() or []
        storage = part.file
        assert isinstance(storage, Sqlite3Reader)
        assert storage_sqlite3.integer_times(storage, [a.id])
        assert not storage_sqlite3.integer_times(storage, [b.id])
        assert not storage_sqlite3.integer_times(storage, [a.id, b.id])


@pytest.mark.parametrize(('stored', 'kind'), [("'text'", 'str'), ('5', 'int')])
def test_a_row_whose_data_is_not_a_blob_is_a_bag_error_naming_it(tmp_path, stored, kind):
    """Read a batch at a time, as message by message (``BagReader.messages``): what the row holds,
    named, rather than a conversion's error from deep inside."""
    bag = tmp_path / 'bag'
    with BagWriter(bag, storage='sqlite3') as writer:
        a = writer.add_topic('/a', 'std_msgs/msg/String')
        for t in (10, 20, 30):
            writer.write(a, t, STRING)
    db = sqlite3.connect(next(bag.glob('*.db3')))
    with db:
        db.execute(f'UPDATE messages SET data={stored} WHERE timestamp=20')
    db.close()
    with BagReader(bag) as reader, pytest.raises(BagError, match=f'bag: a message of topic id {a.id} is stored as '
                                                                f'{kind}, not bytes'):
        (part,) = reader.parts() or []
        assert isinstance(part.file, Sqlite3Reader)
        list(storage_sqlite3.batches(part.file.dbconn, part.conns, name=str(bag)))
