"""``BagReader.messages`` through its storage plugins (mcap a chunk at a time, sqlite3 rows through a
connection of the reading process, ROS 1 chunk by chunk), how every command reads a bag, against
rosbags' own reader of each storage file: the same topics, record times, bytes and order, or a
BagError both ways, on real recordings with malformed messages among them, with a second connection
of a topic, crafted mcap files, windows and topic subsets; ``estimate_bag`` finds the same through
them, and through the estimate's one-call evt3 decode, as through rosbags' reader and ``decode``
message by message."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import re
import sqlite3
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from evsync_ros.bag import events, pipeline, reader
from evsync_ros.bag import restamp as restamp_module
from evsync_ros.bag.estimate import estimate_bag
from evsync_ros.bag.files import Part
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.bag.storage import Storage
from evsync_ros.bag.storage_ros1 import StreamingRos1
from evsync_ros.bag.storage_sqlite3 import bad_row
from evsync_ros.bag.writer import BagWriter
from evsync_ros.errors import BagError
from evsync_testing import crafted
from evsync_testing.chunkcopies import mixed_rows, write_mixed
from evsync_testing.crafted import MCAP_CASES, STRING
from msg_adapters import _kernels
from msg_adapters.registry import is_event_type


@pytest.fixture(scope='module')
def mixed(real_data, tmp_path_factory) -> dict[str, Path]:
    """``chunkcopies``' mixed bag (two real recordings, cut, garbled and foreign messages, a second
    connection of the evt3 topic) in each storage."""
    rows = mixed_rows(real_data)
    folder = tmp_path_factory.mktemp('mixed')
    return {storage: write_mixed(folder / storage, rows, storage=storage) for storage in ('mcap', 'sqlite3')} | {
        'ros1': write_mixed(folder / 'in.bag', rows)}


class _Rosbags:
    """The plugins' reference: a rosbag2 storage file read by rosbags' own reader of it (a crafted
    sqlite3 row refused as the plugins refuse it), a ROS 1 bag as its plugin reads it."""

    ros1 = reader.PLUGINS[Storage.ROS1]

    def messages(self, part: Part, *, window: tuple[int, int] | None, native: bool) -> Iterator[Any]:
        if part.storage is Storage.ROS1:
            yield from self.ros1.messages(part, window=window, native=native)
            return
        start, stop = window if window is not None else (None, None)
        assert not isinstance(part.file, StreamingRos1)
        for conn, stamp, data in part.file.messages([c for c in part.file.connections if c.id in part.conns],
                                                    start, stop):
            error = bad_row(part.path, conn.topic, stamp, data)
            if error is not None:
                raise error
            yield part.conns[conn.id], stamp, data

    def chunks(self, part: Part) -> None:
        return None


@contextlib.contextmanager
def rosbags_reads(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Every storage file read by rosbags' own reader (``_Rosbags``), not its plugin, meanwhile."""
    with monkeypatch.context() as m:
        for storage in Storage:
            m.setitem(reader.PLUGINS, storage, _Rosbags())
        yield


def read_both_ways(bag: Path, monkeypatch: pytest.MonkeyPatch, topics: list[str] | None = None,
                   window_s: tuple[float, float] | None = None) -> tuple[list | str, list | str, bool]:
    """What ``BagReader.messages`` yields through the plugins and through rosbags' reader (or
    'BagError'), and whether the storage's chunks can be read."""
    with BagReader(bag) as bag_reader:
        types = {c.topic: c.msgtype for c in bag_reader.connections if topics is None or c.topic in topics}
        window = bag_reader.window_ns(*window_s) if window_s else None
        chunked = bag_reader.chunks(types) is not None
        out: list[list | str] = []
        for way in (contextlib.nullcontext(), rosbags_reads(monkeypatch)):
            try:
                with way:
                    out.append([(c.topic, c.msgtype, s, bytes(r))
                                for c, s, r in bag_reader.messages(list(types), window=window)])
            except BagError:
                out.append('BagError')
    return out[0], out[1], chunked


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3', 'ros1'])
@pytest.mark.parametrize('subset', ['all', 'events', 'one'])
@pytest.mark.parametrize('window_s', [None, (0.3, 0.5)])
def test_the_mixed_bag_reads_as_rosbags_reads_it(mixed, monkeypatch, storage, subset, window_s):
    with BagReader(mixed[storage]) as bag_reader:
        topics = sorted({c.topic for c in bag_reader.connections})
    chosen = {'all': None, 'events': [t for t in topics if t.endswith('events')], 'one': topics[:1]}[subset]
    ours, theirs, chunked = read_both_ways(mixed[storage], monkeypatch, chosen, window_s)
    assert chunked
    assert isinstance(ours, list) and len(ours) > (10 if window_s else 100)
    assert ours == theirs


@pytest.mark.parametrize('name', ['evt3_sqlite3', 'libcaer_cmp_mcap', 'dvs128_stereo/fan', 'evk4_hd'])
def test_real_recordings_read_as_rosbags_reads_them(real_data, monkeypatch, name):
    ours, theirs, chunked = read_both_ways(real_data / name, monkeypatch)
    assert chunked and isinstance(ours, list) and ours and ours == theirs


@pytest.mark.parametrize('name', list(MCAP_CASES))
def test_crafted_mcap_reads_as_rosbags_reads_it(tmp_path, monkeypatch, name):
    """What rosbags' writer never writes but an mcap file can hold: read as rosbags' reader reads it,
    left to that reader, or refused both ways."""
    chunked, damage = crafted.mcap_case(tmp_path / 'in', name)
    ours, theirs, taken = read_both_ways(tmp_path / 'in', monkeypatch)
    assert taken == chunked
    assert ours == theirs
    assert (ours == 'BagError') == damage


def _spied(calls: list[int], real: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    calls.append(1)
    return real(*args, **kwargs)


def _found(bag: Path, *, parallel: bool = False) -> dict:
    """Everything ``estimate_bag`` reports, as comparable values (read in this process, or with
    ``parallel`` in a second one where the bag allows it)."""
    found = estimate_bag(bag, parallel=parallel)
    return {f.name: repr(getattr(found, f.name)) for f in dataclasses.fields(found)} | {
        'rig': found.rig.as_json(), 'reports': {t: repr(vars(r)) for t, r in found.reports.items()}}


def test_a_ros1_bag_reads_its_own_bytes_converted_as_it_reads_them(mixed):
    with BagReader(mixed['ros1']) as bag_reader:
        ours = [(c.msgtype, bytes(r)) for c, _, r in bag_reader.messages(native=True)]
        converted = [bytes(bag_reader.converted(r, m)) for m, r in ours]
        assert converted == [bytes(r) for _, _, r in bag_reader.messages()]
    assert len(ours) > 100 and converted != [r for _, r in ours]


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3', 'ros1'])
def test_the_estimate_finds_the_same_read_and_decoded_message_by_message(mixed, real_data, tmp_path, monkeypatch,
                                                                         storage):
    bags = [mixed[storage]] + ([real_data / 'evk4_hd', real_data / 'dvs128_stereo' / 'fan'] if storage == 'mcap'
                               else [])
    kernel, taken = _kernels.evt3_packet_decode, []

    def counted(*args):
        out = kernel(*args)
        taken.append((bool(args[-1]) if len(args) > 10 else False, out is not None))
        return out

    for bag in bags:
        with BagReader(bag) as bag_reader:
            assert any(is_event_type(c.msgtype) for c in bag_reader.connections)
        with monkeypatch.context() as m:
            m.setattr(_kernels, 'evt3_packet_decode', counted)
            ours = _found(bag)
        assert (storage == 'ros1', True) in taken  # the one-call decode took packets (a ROS 1 bag's as they are)
        with monkeypatch.context() as m, rosbags_reads(m):
            m.setattr(_kernels, 'evt3_packet_decode', lambda *a: None)
            m.setattr(_kernels, 'event_array_times', lambda *a: None)
            theirs = _found(bag)
        assert ours == theirs, bag
        forks: list[int] = []
        with monkeypatch.context() as m:
            m.setattr(pipeline, 'pipelined', functools.partial(_spied, forks, pipeline.pipelined))
            read_ahead = _found(bag, parallel=True)  # read and decoded in a second process (sqlite3: its own)
        assert read_ahead == ours and forks == [1] * int(ours['passes']), bag  # each read forked once


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_a_window_takes_its_start_and_leaves_its_end(tmp_path, monkeypatch, storage):
    with BagWriter(tmp_path / 'in', storage=storage) as writer:
        conn = writer.add_topic('/s', 'std_msgs/msg/String')
        for t in (10, 20, 30, 40, 50):
            writer.write(conn, t, STRING)
    with BagReader(tmp_path / 'in') as bag_reader:
        assert bag_reader.chunks({'/s': 'std_msgs/msg/String'}) is not None
        ours = [t for _, t, _ in bag_reader.messages(['/s'], window=(20, 40))]
        with rosbags_reads(monkeypatch):
            theirs = [t for _, t, _ in bag_reader.messages(['/s'], window=(20, 40))]
    assert ours == theirs == [20, 30]


def _damaged_late_chunk(path: Path) -> Path:
    """An lz4 mcap file of a chunk at 10 and one of 50 messages from 100, the second damaged."""
    crafted.mcap(path / 'in.mcap', [(1, '/s')], [[(1, 10, STRING)], [(1, 100 + i, STRING) for i in range(50)]],
                 compression='lz4')
    data = bytearray((path / 'in.mcap').read_bytes())
    at = data.rfind(b'\x04\x22\x4d\x18')  # the second chunk's lz4 frame
    data[at + 20:at + 60] = bytes(40)
    (path / 'in.mcap').write_bytes(bytes(data))
    return path


def _sqlite_edited(path: Path, sql: str) -> Path:
    with BagWriter(path, storage='sqlite3') as writer:
        conn = writer.add_topic('/s', 'std_msgs/msg/String')
        for t in (10, 20, 30, 40):
            writer.write(conn, t, STRING)
    with sqlite3.connect(next(path.glob('*.db3'))) as db:
        db.execute(sql)
    return path


def test_a_window_reads_what_rosbags_reads_of_a_file_that_is_odd_elsewhere(tmp_path, monkeypatch):
    """With a window rosbags' reader reads the window's chunks and rows alone, and takes the window's
    messages whatever a chunk's index says: damage, or a row that is not a message, outside the
    window is not met; a message outside its chunk's indexed span but in the window is read."""
    channels, chunks, options, _ = MCAP_CASES['a message past its chunk index span: rosbags drops it']
    crafted.mcap(tmp_path / 'span' / 'in.mcap', channels, chunks, **options)
    bags = {'span': tmp_path / 'span', 'damaged': _damaged_late_chunk(tmp_path / 'damaged'),
            'text': _sqlite_edited(tmp_path / 'text', "UPDATE messages SET data='x' WHERE timestamp=30")}
    for name, bag in bags.items():
        with BagReader(bag) as bag_reader:
            window = (0, 100) if name == 'span' else (10, 28)
            ours = [t for _, t, _ in bag_reader.messages(['/s'], window=window)]
            with rosbags_reads(monkeypatch):
                theirs = [t for _, t, _ in bag_reader.messages(['/s'], window=window)]
        assert ours == theirs and ours, name


def test_a_record_time_that_is_not_an_integer_is_read_as_rosbags_reads_it(tmp_path, monkeypatch):
    """A sqlite3 time stored as REAL (rosbags' writer never does): the file is read row by row."""
    bag = _sqlite_edited(tmp_path / 'real', 'UPDATE messages SET timestamp=25.5 WHERE timestamp=20')
    with BagReader(bag) as bag_reader:
        assert bag_reader.chunks({'/s': 'std_msgs/msg/String'}) is None  # restamp copies it message by message
        assert [t for _, t, _ in bag_reader.messages()] == [10, 25.5, 30, 40]
        with rosbags_reads(monkeypatch):
            assert [t for _, t, _ in bag_reader.messages()] == [10, 25.5, 30, 40]


def test_a_ros1_bag_whose_types_the_adapters_do_not_convert_is_converted_first(mixed, monkeypatch):
    """Where the bag defines an event type otherwise than the adapters read it (``adapters_convert``
    false: rosbags' converter takes it), its ROS 1 bytes are never decoded as they are."""
    ours = _found(mixed['ros1'])
    calls: list[bool] = []
    kernel = _kernels.evt3_packet_decode

    def counted(*args):
        calls.append(bool(args[-1]) if len(args) > 10 else False)
        return kernel(*args)

    monkeypatch.setattr(events, 'adapters_convert', lambda store, msgtype: False)
    monkeypatch.setattr(_kernels, 'evt3_packet_decode', counted)
    monkeypatch.setattr(_kernels, 'event_array_times', lambda raw, ros1: pytest.fail('ROS 1 bytes decoded') if ros1
                        else None)
    assert _found(mixed['ros1']) == ours
    assert calls and not any(calls)


@pytest.mark.parametrize(('stored', 'shown'), [("'20 ns'", "'20 ns'"), ('9.3e18', '9.3e+18')])
def test_a_record_time_that_is_not_a_number_is_a_bag_error_naming_the_bag(tmp_path, monkeypatch, stored, shown):
    """A sqlite3 time stored as TEXT, or as a REAL beyond int64: read, restamped (into sqlite3 and
    mcap) and estimated, a BagError naming the bag (no output left), not a conversion's error from
    deep inside."""
    bag = _sqlite_edited(tmp_path / 'odd', f'UPDATE messages SET timestamp={stored} WHERE timestamp=20')
    said = f'odd: a message of /s has the record time {shown}, not a number of nanoseconds in int64'
    for way in (contextlib.nullcontext(), rosbags_reads(monkeypatch)):
        with way, BagReader(bag) as bag_reader, pytest.raises(BagError, match=re.escape(said)):
            list(bag_reader.messages())
    for storage in ('sqlite3', 'mcap'):
        with pytest.raises(BagError, match=re.escape(said)):
            restamp_bag(bag, tmp_path / 'out', corrections={}, reference='/s', storage=storage)
        assert not (tmp_path / 'out').exists()


def test_a_row_whose_data_is_not_a_blob_is_a_bag_error_naming_the_bag_on_every_read(tmp_path, monkeypatch):
    """A sqlite3 row whose data is TEXT: the plugin's row-by-row read, rosbags' reader and the restamp
    each refuse it, naming the bag and the topic, rather than yield it or fail deep inside."""
    bag = _sqlite_edited(tmp_path / 'odd', "UPDATE messages SET data='not a blob' WHERE timestamp=20")
    said = 'odd: a message of /s is stored as str, not bytes'
    with BagReader(bag) as bag_reader:
        for way in (contextlib.nullcontext(), rosbags_reads(monkeypatch)):
            with way, pytest.raises(BagError, match=re.escape(said)):
                list(bag_reader.messages())
    with pytest.raises(BagError, match=re.escape(said)):
        restamp_bag(bag, tmp_path / 'out', corrections={}, reference='/s', storage='sqlite3')
    assert not (tmp_path / 'out').exists()


@pytest.mark.parametrize('chunked', [True, False])
def test_a_negative_record_time_is_refused_by_an_mcap_output_naming_it(tmp_path, monkeypatch, chunked):
    """mcap's times are unsigned: a rosbag2's negative record time (int64) cannot go into one. A
    BagError naming the output and the message's topic, written a chunk at a time or message by
    message, and no output left; a sqlite3 output takes it as it is."""
    bag = _sqlite_edited(tmp_path / 'neg', 'UPDATE messages SET timestamp=-1000 WHERE timestamp=20')
    if not chunked:
        monkeypatch.setattr(restamp_module, '_chunked', lambda *a, **k: None)
    with pytest.raises(BagError, match='out: a message of /s has the record time -1000, before 0'):
        restamp_bag(bag, tmp_path / 'out', corrections={}, reference='/s', storage='mcap')
    assert not (tmp_path / 'out').exists()
    restamp_bag(bag, tmp_path / 'kept', corrections={}, reference='/s', storage='sqlite3')
    with BagReader(tmp_path / 'kept') as bag_reader:
        assert [t for _, t, _ in bag_reader.messages()] == [-1000, 10, 30, 40]
