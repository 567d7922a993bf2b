"""Issue 52: a rosbag2 output compressed and split as ``ros2 bag record`` writes one (--compression-mode,
--compression-format, --max-bag-size, --max-bag-duration): rosbags compresses; the splitting is
evsync's own (rosbags cannot), one storage file per split, named as rosbag2 names them, one
metadata.yaml listing them; the same messages as one plain file; every command reads it; nothing at
the destination until it is whole."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from ruamel.yaml import YAML

from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.bag.writer import BagWriter, Compression, Layout
from evsync_ros.cli.main import main
from evsync_ros.errors import BagError
from msg_adapters.definitions import EVENT_PACKET

S = 1_000_000_000


@pytest.fixture(scope='module')
def rig(tmp_path_factory) -> Path:
    bag = tmp_path_factory.mktemp('rig') / 'rig'
    assert main(['simulate', str(bag), '--preset', 'same-model', '--duration', '12']) == 0
    return bag


def read_all(bag: Path) -> list[tuple[str, int, bytes]]:
    with BagReader(bag) as reader:
        return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]


def info(bag: Path) -> dict:
    return YAML(typ='safe').load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']


def synthetic(path: Path, layout: Layout, *, storage: str = 'sqlite3', n: int = 50, size: int = 1000,
              step_ns: int = S // 10) -> list[tuple[int, int]]:
    """``n`` messages of ``size`` bytes, ``step_ns`` apart, on two topics; (record time, length) of each."""
    rng = np.random.default_rng(1)
    written = []
    with BagWriter(path, storage=storage, layout=layout) as w:
        conns = [w.add_topic(t, EVENT_PACKET) for t in ('/a', '/b')]
        for k in range(n):
            w.write(conns[k % 2], 100 * S + k * step_ns, rng.bytes(size))
            written.append((100 * S + k * step_ns, size))
    return written


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_split_by_size_as_rosbag2_splits(tmp_path, storage):
    """Each file takes messages until they hold --max-bag-size bytes; the next one begins the next
    file. The files are named NAME_0, NAME_1, ... and metadata.yaml lists them with their counts."""
    out = tmp_path / 'out'
    synthetic(out, Layout(max_bytes=10_000), storage=storage, n=50, size=1000)
    suffix = '.db3' if storage == 'sqlite3' else '.mcap'
    meta = info(out)
    assert meta['relative_file_paths'] == [f'out_{i}{suffix}' for i in range(5)]
    assert sorted(p.name for p in out.iterdir()) == sorted([*meta['relative_file_paths'], 'metadata.yaml'])
    assert [f['message_count'] for f in meta['files']] == [10] * 5
    assert meta['message_count'] == 50 and [t['message_count'] for t in meta['topics_with_message_count']] == [25, 25]
    assert meta['starting_time']['nanoseconds_since_epoch'] == 100 * S
    assert meta['duration']['nanoseconds'] == 49 * S // 10
    for i, name in enumerate(meta['relative_file_paths']):  # each file alone: its own ten messages
        with BagReader(out / name) as reader:
            times = [t for _, t, _ in reader.messages()]
        assert times == [100 * S + (10 * i + k) * S // 10 for k in range(10)]
    assert [t for _, t, _ in read_all(out)] == [100 * S + k * S // 10 for k in range(50)]


def test_split_by_duration_and_whichever_comes_first(tmp_path):
    """--max-bag-duration: a new file once the next message is more than it after the file's first."""
    out = tmp_path / 'out'
    synthetic(out, Layout(max_duration_ns=S), n=50)  # 0.1 s apart: 11 messages span 1 s, the 12th is past it
    assert [f['message_count'] for f in info(out)['files']] == [11, 11, 11, 11, 6]
    both = tmp_path / 'both'
    synthetic(both, Layout(max_duration_ns=S, max_bytes=5000), n=50)  # size first: 5 messages a file
    assert [f['message_count'] for f in info(both)['files']] == [5] * 10


@pytest.mark.parametrize(('mode', 'suffix'), [(Compression.FILE, '.db3.zstd'), (Compression.MESSAGE, '.db3')])
def test_compressed_and_split_read_back_the_same(tmp_path, mode, suffix):
    plain, packed = tmp_path / 'plain', tmp_path / 'packed'
    synthetic(plain, Layout())
    synthetic(packed, Layout(compression=mode, compression_format='zstd', max_bytes=20_000))
    meta = info(packed)
    assert meta['compression_mode'] == mode.value and meta['compression_format'] == 'zstd'
    assert meta['relative_file_paths'] == [f'packed_{i}{suffix}' for i in range(3)]
    assert read_all(packed) == read_all(plain)
    with Reader(packed) as theirs:  # rosbags' own reader, as any rosbag2 tool reads it
        assert theirs.message_count == 50 and len(list(theirs.messages())) == 50


def test_an_unsplit_plain_output_is_as_before(tmp_path):
    """No layout asked: rosbags' one file, NAME.db3, as every restamped output so far."""
    out = tmp_path / 'out'
    synthetic(out, Layout())
    assert sorted(p.name for p in out.iterdir()) == ['metadata.yaml', 'out.db3']


@pytest.mark.parametrize(('layout', 'said'), [
    (Layout(compression_format='zstd'), 'needs a --compression-mode'),
    (Layout(compression=Compression.FILE), 'needs --compression-format zstd'),
    (Layout(max_bytes=-1), r'0 \(no splitting\) or more'),
])
def test_a_layout_that_cannot_be_written_is_refused_before_anything_is(tmp_path, layout, said):
    with pytest.raises(BagError, match=said):
        BagWriter(tmp_path / 'out', layout=layout)
    assert list(tmp_path.iterdir()) == []


def test_a_ros1_output_says_what_it_takes(tmp_path):
    with pytest.raises(BagError, match='a ROS 1 bag .* one uncompressed file; compression and splitting are for a '
                                       'rosbag2 output'):
        BagWriter(tmp_path / 'out.bag', storage='ros1', layout=Layout(max_bytes=1000))


def test_a_split_output_interrupted_leaves_nothing(tmp_path):
    """Files already split off are no output: nothing at the destination, no partial directory."""
    out = tmp_path / 'out'

    def interrupted() -> None:
        with BagWriter(out, layout=Layout(max_bytes=2000)) as w:
            conn = w.add_topic('/a', EVENT_PACKET)
            for k in range(20):
                w.write(conn, 100 * S + k, bytes(1000))
            assert w._parts is not None and len(w._parts.dirs) > 5
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        interrupted()
    assert list(tmp_path.iterdir()) == []


def test_restamp_splits_and_compresses_the_same_messages(rig, tmp_path):
    """A restamped rig written plain, split, and split with each file compressed: the same messages,
    the same provenance, and the estimate of each the same."""
    from evsync_ros.bag.estimate import estimate_bag

    est = estimate_bag(rig)
    outs = {'plain': Layout(), 'split': Layout(max_bytes=4_000_000),
            'mcap': Layout(max_duration_ns=3 * S, compression=Compression.FILE, compression_format='zstd')}
    reports = {name: restamp_bag(rig, tmp_path / name, corrections=est.rig.corrections, reference=est.rig.reference,
                                 storage='mcap' if name == 'mcap' else None, layout=layout)
               for name, layout in outs.items()}
    assert len(reports['split'].files) >= 3 and len(reports['mcap'].files) >= 4
    assert reports['mcap'].files[0] == 'mcap_0.mcap.zstd'
    plain = read_all(tmp_path / 'plain')
    for name in ('split', 'mcap'):
        assert sorted(read_all(tmp_path / name)) == sorted(plain)
        with BagReader(tmp_path / name) as reader:
            assert reader.provenance is not None and reader.provenance['reference'] == est.rig.reference
    answers = {name: estimate_bag(tmp_path / name).rig.as_json() for name in outs}
    assert answers['split'] == answers['plain'] == answers['mcap']


def test_the_commands_write_and_read_split_bags(rig, tmp_path, capsys):
    out = tmp_path / 'out'
    assert main(['restamp', str(rig), str(out), '--max-bag-size', '5000000', '--compression-mode', 'message',
                 '--compression-format', 'zstd']) == 0
    said = capsys.readouterr().out
    files = info(out)['relative_file_paths']
    assert len(files) >= 2 and f'wrote {out} (sqlite3, {len(files)} files, zstd per message)' in said
    assert main(['estimate', str(out), '--json']) == 0
    first = json.loads(capsys.readouterr().out)
    assert all(c['accepted'] for c in first['cameras'])
    assert main(['report', str(out)]) == 0
    assert 'was restamped by evsync' in capsys.readouterr().out
    assert main(['restamp', str(rig), str(tmp_path / 'x'), '--compression-format', 'zstd']) == 2
    assert 'needs a --compression-mode' in capsys.readouterr().err
    assert main(['restamp', str(rig), str(tmp_path / 'x.bag'), '--max-bag-duration', '5']) == 2
    assert 'a ROS 1 bag (.bag)' in capsys.readouterr().err
    assert not (tmp_path / 'x').exists() and not (tmp_path / 'x.bag').exists()
