"""Provenance (issue 24): a restamped rosbag2 records in its metadata what was applied, read back by
BagReader and shown by ``evsync report``; restamping a restamped bag warns. A ROS 1 bag has no
metadata, and says so."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from ruamel.yaml import YAML

from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.cli.main import main
from evsync_ros.core.clock import ClockCorrection


@pytest.fixture(scope='module')
def rig(tmp_path_factory) -> tuple[Path, dict]:
    bag = tmp_path_factory.mktemp('provenance') / 'rig'
    assert main(['simulate', str(bag), '--preset', 'same-model', '--duration', '12', '--storage', 'mcap']) == 0
    return bag, json.loads((bag.parent / 'rig.truth.json').read_text())


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_what_was_applied_round_trips_through_the_metadata(rig, tmp_path, storage):
    bag, truth = rig
    other = next(c['topic'] for c in truth['cameras'] if c['topic'] != truth['reference'])
    corr = {other: ClockCorrection(offset_ns=-1_234_567_891, skew_ppm=12.5, anchor_ns=42)}
    out = tmp_path / 'out'
    rep = restamp_bag(bag, out, corrections=corr, reference=truth['reference'], storage=storage,
                      provenance={'method': 'refined', 'estimate': {'reference': truth['reference']}})
    with BagReader(bag) as reader:
        assert reader.provenance is None  # the input: never restamped, never touched
    with BagReader(out) as reader:
        record = reader.provenance
    assert record == rep.provenance
    assert record['corrections'] == {other: {'offset_ns': -1_234_567_891, 'skew_ppm': 12.5, 'anchor_ns': 42}}
    assert record['reference'] == truth['reference'] and record['input'] == str(bag.resolve())
    assert record['method'] == 'refined' and record['estimate'] == {'reference': truth['reference']}
    assert record['evsync_version'] and record['written_utc']


def test_a_ros1_output_says_it_has_nowhere_to_record_it(rig, tmp_path):
    bag, truth = rig
    rep = restamp_bag(bag, tmp_path / 'out.bag', corrections={}, reference=truth['reference'])
    assert rep.provenance is None
    with BagReader(tmp_path / 'out.bag') as reader:
        assert reader.provenance is None


def test_report_shows_it_and_restamping_again_warns(rig, tmp_path, capsys):
    bag, truth = rig
    out, again = tmp_path / 'out', tmp_path / 'again'
    assert main(['restamp', str(bag), str(out), '--reference', truth['reference']]) == 0
    assert 'what was applied is in its metadata' in capsys.readouterr().out
    assert main(['report', str(out), '--reference', truth['reference']]) in (0, 1)
    shown = capsys.readouterr().out
    assert f'{out} was restamped by evsync' in shown and f'from {bag.resolve()}, method refined' in shown
    with BagReader(out) as reader:
        applied = reader.provenance['corrections']
    for topic in applied:
        assert topic in shown
    assert main(['restamp', str(out), str(again), '--reference', truth['reference']]) == 0
    err = capsys.readouterr().err
    assert f'{out} was restamped by evsync already' in err
    with BagReader(again) as reader:  # the second restamp records its own input: the first output
        assert reader.provenance['input'] == str(out.resolve())


def test_a_provenance_that_is_not_json_is_named(rig, tmp_path):
    bag, truth = rig
    out = tmp_path / 'out'
    restamp_bag(bag, out, corrections={}, reference=truth['reference'], storage='sqlite3')
    meta = out / 'metadata.yaml'
    yaml = YAML(typ='safe')
    doc = yaml.load(meta.read_text())
    assert 'evsync' in doc['rosbag2_bagfile_information']['custom_data']
    doc['rosbag2_bagfile_information']['custom_data']['evsync'] = '{not json'
    with meta.open('w') as f:
        yaml.dump(doc, f)
    from evsync_ros.errors import BagError
    with BagReader(out) as reader, pytest.raises(BagError, match='provenance is not JSON'):
        _ = reader.provenance
