"""bench/stages.py (what ``bench/restamp.py --profile`` runs): on a small simulated bag, each command's
time lands in the stages that command has (restamp: read, restamp, write; estimate: read, decode,
binning, fitting), none in the others, and the stages add up to no more than the command took."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from evsync_ros.sim.pixelsim import preset, simulate
from evsync_ros.sim.simbag import write_rig

STAGES_PY = Path(__file__).parents[2] / 'bench' / 'stages.py'


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    d = tmp_path_factory.mktemp('stages')
    rig = preset('same-model', seed=1, duration_s=6)
    truth = write_rig(rig, simulate(rig), d / 'sim')
    (d / 'offsets.json').write_text(json.dumps(truth))
    return d, rig.reference


def staged(tmp_path: Path, *argv: str) -> dict[str, float]:
    out = tmp_path / 'stages.json'
    subprocess.run([sys.executable, str(STAGES_PY), '--out', str(out), '--', *argv], check=True,
                   stdout=subprocess.DEVNULL)
    return json.loads(out.read_text())


def test_restamp_time_is_reading_restamping_and_writing(tmp_path, bag):
    d, reference = bag
    stages = staged(tmp_path, 'restamp', str(d / 'sim'), str(tmp_path / 'out'), '--offsets', str(d / 'offsets.json'),
                    '--reference', reference)
    assert (tmp_path / 'out' / 'metadata.yaml').is_file()
    for stage in ('storage read', 'restamp', 'storage write', 'other'):
        assert stages[stage] > 0, stage
    for stage in ('ROS 1 conversion', 'decode', 'binning', 'fitting'):
        assert stages[stage] == 0, stage
    main = stages.pop('_main')
    assert sum(stages.values()) <= main


def test_estimate_time_is_reading_decoding_binning_and_fitting(tmp_path, bag):
    d, reference = bag
    stages = staged(tmp_path, 'estimate', str(d / 'sim'), '--reference', reference)
    for stage in ('storage read', 'decode', 'binning', 'fitting', 'other'):
        assert stages[stage] > 0, stage
    for stage in ('ROS 1 conversion', 'restamp', 'storage write'):
        assert stages[stage] == 0, stage
    main = stages.pop('_main')
    assert sum(stages.values()) <= main
