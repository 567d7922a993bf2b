"""The bag tools under faults: truncated and corrupted storage, no metadata.yaml, an existing output, a
write that fails, and SIGKILL at random points. After each, the input is untouched and no output is
left that looks complete (``bagfaults`` judges; ``bench/faults.py`` runs many more of each)."""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest

from evsync_ros.bag import estimate
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.writer import BagWriter, remove_stale_partials
from evsync_ros.errors import BagError
from evsync_testing import bagfaults
from msg_adapters.definitions import DVS_EVENT_ARRAY
from msg_adapters.event_array import parse_event_array


@pytest.fixture(scope='module')
def rigs(tmp_path_factory):
    return bagfaults.rigs(tmp_path_factory.mktemp('rigs'), seed=2)


def assert_survived(trials):
    for t in trials:
        assert t.survived, f'{t.fault}: {t.outcome}: {t.detail}'


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
@pytest.mark.parametrize('fraction', [0.0, 0.1, 0.5, 0.97])
def test_truncated_storage(rigs, tmp_path, storage, fraction):
    bags, offsets = rigs
    trials = bagfaults.truncated(bags[storage], tmp_path, fraction=fraction, offsets=offsets)
    assert_survived(trials)
    assert trials[-1].outcome == 'refused'  # a cut file is never restamped as if whole


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
@pytest.mark.parametrize('seed', [1, 2, 3])
def test_corrupted_storage(rigs, tmp_path, storage, seed):
    bags, offsets = rigs
    assert_survived(bagfaults.corrupted(bags[storage], tmp_path, seed=seed, offsets=offsets))


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
@pytest.mark.parametrize('seed', [1, 2])
def test_a_message_every_reader_passes_over_is_refused_not_lost(rigs, tmp_path, storage, seed):
    bags, offsets = rigs
    trials = bagfaults.passed_over(bags[storage], tmp_path, seed=seed, offsets=offsets)
    assert_survived(trials)
    assert [t.outcome for t in trials] == ['refused', 'refused']


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_a_bag_without_metadata_is_read_from_its_storage_files(rigs, tmp_path, storage):
    bags, offsets = rigs
    assert_survived(bagfaults.missing_metadata(bags[storage], tmp_path, offsets=offsets))


def test_an_existing_output_is_refused_and_left_as_it_was(rigs, tmp_path):
    bags, offsets = rigs
    assert_survived(bagfaults.existing_output(bags['sqlite3'], tmp_path, offsets=offsets))


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
@pytest.mark.parametrize('fraction', [0.01, 0.5])
def test_a_failing_write_leaves_nothing(rigs, tmp_path, storage, fraction):
    bags, offsets = rigs
    [trial] = bagfaults.write_failure(bags[storage], tmp_path, fraction=fraction, offsets=offsets)
    assert trial.survived and trial.outcome == 'refused', trial


@pytest.mark.parametrize('delay_s', [0.2, 0.6, 0.9])
def test_sigkill_leaves_no_output_and_the_next_run_cleans_up(rigs, tmp_path, delay_s):
    bags, offsets = rigs
    assert_survived(bagfaults.killed(bags['mcap'], tmp_path, delay_s=delay_s, offsets=offsets))


def test_stale_partials_of_a_live_writer_are_kept(tmp_path):
    mine = tmp_path / f'.out.{os.getpid()}.abc.partial'
    dead = tmp_path / '.out.999999999.abc.partial'
    other = tmp_path / '.other.999999999.abc.partial'
    for d in (mine, dead, other):
        d.mkdir()
    assert remove_stale_partials(tmp_path / 'out') == [dead]
    assert mine.exists() and other.exists() and not dead.exists()


def test_corrupt_event_times_are_counted_and_the_estimate_holds(rigs, tmp_path):
    """Messages whose events carry times years away (a corrupt word, a bad driver): counted as far,
    not binned, and the offsets are what the intact bag gives."""
    bags, _ = rigs
    bad = tmp_path / 'bad'
    rng = np.random.default_rng(0)
    spoiled = 0
    with BagReader(bags['sqlite3']) as reader, BagWriter(bad) as writer:
        conns = {c.topic: writer.add_topic(c.topic, c.msgtype) for c in reader.connections}
        for conn, stamp, raw in reader.messages():
            copy = bytearray(raw)
            if conn.msgtype == DVS_EVENT_ARRAY and rng.random() < 0.3:
                view = parse_event_array(copy)
                for k in rng.integers(0, view.count, 3):  # ts.sec of three events: anywhere in int32
                    at = view.first + 16 * k + 4
                    copy[at:at + 4] = rng.integers(-2**31, 2**31).astype('<i4').tobytes()
                    spoiled += 1
            writer.write(conns[conn.topic], stamp, copy)
    good, worse = estimate.estimate_bag(bags['sqlite3']), estimate.estimate_bag(bad)
    for a, b in zip(good.rig.cameras, worse.rig.cameras):
        assert b.accepted and abs(a.offset_ns - b.offset_ns) < 100_000, (a, b)
    assert 0.8 * spoiled < sum(worse.far_events.values()) <= spoiled
    assert worse.peak_bin_bytes < 2 * good.peak_bin_bytes


def test_bag_errors_name_the_bag(tmp_path):
    empty = tmp_path / 'empty'
    empty.mkdir()
    with pytest.raises(BagError, match='empty: no metadata.yaml and no .mcap or .db3'):
        BagReader(empty)


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_a_storage_file_cut_short_is_said_to_be_corrupt_or_truncated(rigs, tmp_path, storage):
    """Not the storage library's words alone ('File end magic is invalid.', 'database disk image is
    malformed'): what they mean for the bag, named."""
    bags, _ = rigs
    cut = tmp_path / 'cut'
    shutil.copytree(bags[storage], cut)
    data = next(f for f in cut.iterdir() if f.suffix in ('.mcap', '.db3'))
    data.write_bytes(data.read_bytes()[:data.stat().st_size // 2])
    with pytest.raises(BagError, match=f'{cut}: cannot be read .*corrupt or truncated'), BagReader(cut):
        pass
