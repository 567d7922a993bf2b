"""--reference host on bags: every camera onto the host clock, checked against the simulator's truth."""

import json

import numpy as np
import pytest

from evsync_ros.bag.estimate import estimate_bag, read_event_times
from evsync_ros.cli import main as cli
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.sim.pixelsim import preset, simulate
from evsync_ros.sim.simbag import write_rig

FLOOR_NS = 400_000
"""The simulated evt3 cameras' least latency from an event to the host (simbag: 0.4 ms + jitter)."""


@pytest.fixture(scope='module')
def drifting(tmp_path_factory):
    d = tmp_path_factory.mktemp('host')
    rig = preset('drift', seed=2, duration_s=30)  # cameras drifting against each other and the host
    return d / 'rig', write_rig(rig, simulate(rig), d / 'rig')


def host_map(cam):
    h = cam['host']
    return ClockCorrection(offset_ns=h['offset_ns'], skew_ppm=h['skew_ppm'], anchor_ns=h['anchor_ns'])


def test_every_camera_lands_on_host_time_late_by_the_latency_floor_only(drifting):
    bag, truth = drifting
    plain = estimate_bag(bag, reference='host')
    floored = estimate_bag(bag, reference='host', host_floor_ns=FLOOR_NS)
    assert plain.rig.reference == 'host' and plain.rig.host is not None
    assert plain.rig.host.residual_ns < 50_000
    times, _ = read_event_times(bag)
    for cam in truth['cameras']:
        t = times[cam['topic']][:: 997]
        want = host_map(cam).apply(t)
        late = plain.rig.camera(cam['topic']).correction.apply(t) - want
        assert late.min() > 0 and late.max() < 1_000_000  # late by about the floor, never early
        err = floored.rig.camera(cam['topic']).correction.apply(t) - want
        assert np.abs(err).max() < 150_000, cam['topic']


def test_restamp_onto_host_moves_every_camera_and_the_json_says_host(drifting, tmp_path, capsys):
    bag, truth = drifting
    assert cli.main(['estimate', str(bag), '--reference', 'host', '--host-latency-us', '400', '--json']) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc['reference'] == 'host' and {'offset_ns', 'skew_ppm', 'residual_ns'} <= set(doc['host'])
    (tmp_path / 'host.json').write_text(json.dumps(doc))
    assert cli.main(['restamp', str(bag), str(tmp_path / 'out'), '--offsets', str(tmp_path / 'host.json')]) == 0
    capsys.readouterr()
    before, _ = read_event_times(bag)
    after, _ = read_event_times(tmp_path / 'out')
    for cam in truth['cameras']:
        err = after[cam['topic']] - host_map(cam).apply(before[cam['topic']])
        assert np.abs(err).max() < 150_000, cam['topic']  # the first camera too: no camera is the reference


def test_host_latency_needs_reference_host(drifting, capsys):
    bag, _ = drifting
    assert cli.main(['estimate', str(bag), '--host-latency-us', '400']) == 2
    assert 'for --reference host' in capsys.readouterr().err
