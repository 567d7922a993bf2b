"""Slow and fast motion, and cameras of another make: the presets and options behind the response-lag
study (issue 38), in the simulator and in ``evsync simulate``, with the truth known."""

import json

import numpy as np
import pytest

from evsync_ros.cli.main import main
from evsync_ros.errors import ParameterError
from evsync_ros.sim.pixelsim import FAST_PX_S, SLOW_PX_S, parse_make, preset, px_per_degree, simulate


def test_two_makes_slow_is_the_issue_s_rig():
    rig = preset('two-makes-slow', seed=4)
    a, b = rig.cameras
    assert (a.contrast, b.contrast) == (0.22, 0.30)
    assert (a.width, a.height) != (b.width, b.height) and b.noise_hz > a.noise_hz
    assert a.lowpass_ns == b.lowpass_ns and a.refractory_ns == b.refractory_ns  # only the threshold's response differs
    assert rig.scene.motion == 'episodes' and rig.scene.shake < 0.3  # a rigid rig panning in bursts
    assert rig.scene.speed_dps * px_per_degree(a) == pytest.approx(SLOW_PX_S)
    fast = preset('two-makes-fast', seed=4)
    assert fast.cameras == rig.cameras  # the same makes, the same clocks
    assert fast.scene.speed_dps * px_per_degree(a) == pytest.approx(FAST_PX_S)
    for name in ('slow-motion', 'fast-motion'):
        same = preset(name, seed=4)
        assert len({(c.contrast, c.width, c.lowpass_ns, c.refractory_ns) for c in same.cameras}) == 1


def test_edge_speed_sets_how_fast_the_scene_moves_through_the_pixels():
    slow = preset('same-model', seed=2, duration_s=4, speed_px_s=10.0)
    fast = preset('same-model', seed=2, duration_s=4, speed_px_s=1000.0)
    ref = slow.camera(slow.reference)
    assert slow.scene.speed_dps == pytest.approx(10.0 / px_per_degree(ref))
    assert fast.cameras == slow.cameras
    n_slow = simulate(slow)[slow.reference].t.size
    n_fast = simulate(fast)[fast.reference].t.size
    # events come from log intensity crossing thresholds: a hundred times the speed, tens of times the events
    assert n_fast > 20 * n_slow
    with pytest.raises(ParameterError, match='speed_px_s'):
        preset('same-model', speed_px_s=0.0)


def test_a_make_changes_every_camera_but_the_reference():
    make = parse_make('contrast=0.45, lowpass-us=1000,refractory-us=0,noise-hz=0.5')
    assert make == {'contrast': 0.45, 'lowpass_ns': 1_000_000, 'refractory_ns': 0, 'noise_hz': 0.5}
    plain = preset('same-model', seed=1)
    rig = preset('same-model', seed=1, make=make)
    assert rig.cameras[0] == plain.cameras[0]
    for cam, was in zip(rig.cameras[1:], plain.cameras[1:]):
        assert (cam.contrast, cam.lowpass_ns, cam.refractory_ns, cam.noise_hz) == (0.45, 1_000_000, 0, 0.5)
        assert (cam.start_ns, cam.clock_at_start_ns, cam.width) == (was.start_ns, was.clock_at_start_ns, was.width)
    for bad, match in (('contrast', 'KEY=VALUE'), ('gain=2', 'KEY=VALUE'), ('contrast=high', 'must be a number'),
                       (' , ', 'nothing to set')):
        with pytest.raises(ParameterError, match=match):
            parse_make(bad)
    with pytest.raises(ParameterError, match='contrast'):
        preset('same-model', make={'contrast': 0.0})


def test_a_higher_threshold_fires_fewer_events_on_the_same_edges():
    rig = preset('same-model', seed=3, duration_s=3, speed_px_s=300.0,
                 make={'contrast': 0.44, 'noise_hz': 0.0, 'hot_pixels': 0})
    events = simulate(rig)
    ref, other = events[rig.cameras[0].topic], events[rig.cameras[1].topic]
    ratio = other.t.size / ref.t.size
    # at most the thresholds' ratio (0.20 / 0.44): small changes that cross the lower threshold never reach the higher
    assert 0.15 < ratio < 0.46


def test_simulate_command_writes_the_make_and_speed_into_the_truth(tmp_path, capsys):
    bag = tmp_path / 'rig'
    assert main(['simulate', str(bag), '--preset', 'two-makes-slow', '--duration', '3', '--speed', '50',
                 '--make', 'lowpass-us=800,refractory-us=1000']) == 0
    truth = json.loads((tmp_path / 'rig.truth.json').read_text())
    a, b = truth['cameras']
    assert (a['contrast'], a['lowpass_ns'], a['refractory_ns']) == (0.22, 300_000, 100_000)
    assert (b['contrast'], b['lowpass_ns'], b['refractory_ns']) == (0.30, 800_000, 1_000_000)
    assert truth['speed_dps'] * a['width'] / 60.0 == pytest.approx(50.0)
    assert np.isfinite(b['offset_ns']) and b['events'] > 0
    assert main(['simulate', str(tmp_path / 'bad'), '--make', 'threshold=0.3']) == 2
    assert 'threshold=0.3' in capsys.readouterr().err
    assert not (tmp_path / 'bad').exists()
