"""The node with trigger edges (``trigger_channels``): two evt3 cameras of other makes with one pulse
wired into both (simulated), played into ``evsync_node`` over DDS at 1x. Once the density decision
picks the pulse, the camera's line comes from its edges: within 10 us of the truth, where the density
alone is hundreds of microseconds off; /diagnostics says how far the density was."""

from __future__ import annotations

from dataclasses import replace

import pytest

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine import feed
from evsync_ros.core.engine.engine import Engine
from evsync_ros.errors import ParameterError
from evsync_ros.ros.parameters import node_config, node_defaults
from evsync_ros.sim.pixelsim import preset, simulate
from evsync_ros.sim.simbag import write_rig
from evsync_testing import paths


@pytest.fixture(scope='module')
def wired(tmp_path_factory):
    """mixed-models' Prophesee-like and DVXplorer-like cameras (evt3, edges in their events), 20 s,
    a 5 Hz pulse into both on channel 0."""
    rig = preset('mixed-models', seed=3, duration_s=20, triggers_hz=5)
    rig = replace(rig, cameras=(rig.cameras[0], rig.cameras[2]))
    bag = tmp_path_factory.mktemp('wired') / 'rig'
    return bag, write_rig(rig, simulate(rig), bag)


def _error_ns(verdict: paths.Verdict, truth: dict) -> float:
    t = next(c for c in truth['cameras'] if c['topic'] == verdict.topic)
    true = ClockCorrection(offset_ns=t['offset_ns'], skew_ppm=t['skew_ppm'], anchor_ns=t['anchor_ns'])
    assert verdict.offset_ns is not None
    mine = ClockCorrection(offset_ns=verdict.offset_ns, skew_ppm=verdict.skew_ppm, anchor_ns=verdict.anchor_ns)
    at = verdict.anchor_ns
    return mine.apply_one(at) - true.apply_one(at)


def test_the_node_locks_from_the_edges(wired):
    bag, truth = wired
    cam = '/dvxplorer/events'
    edges = paths.through_node(bag, reference=truth['reference'],
                               extra={'trigger_channels': [f'{truth["reference"]}=0', f'{cam}=0']})
    plain = paths.through_node(bag, reference=truth['reference'])
    on_edges, alone = edges.verdicts[cam], plain.verdicts[cam]
    assert on_edges.accepted and alone.accepted, (on_edges, alone)
    print(f'{cam}: {_error_ns(on_edges, truth) / 1e3:+.2f} us off the truth on edges, '
          f'{_error_ns(alone, truth) / 1e3:+.1f} us on the density alone')
    assert abs(_error_ns(on_edges, truth)) <= 10_000, (on_edges, _error_ns(on_edges, truth))
    assert abs(_error_ns(alone, truth)) > 30_000  # the makes' lag, which only the edges see
    said = edges.reports[-1][1][cam]
    assert int(said['trigger_edges']) > 50
    assert abs(float(said['density_minus_edges_us']) * 1e3 - _error_ns(alone, truth)) < 200_000


def test_two_cameras_each_tie_their_edges_in_the_engine():
    """The engine's rule alone: edges before a density decision change nothing (they do not pick a
    pulse); a stream not tracked is refused."""
    import numpy as np
    e = Engine(['/a', '/b'], reference='/a')
    feed.add_edges(e, '/b', np.array([1, 2], np.int64), np.array([1, 0], np.uint8))
    assert e.stream('/b').lock.correction is None and e.stream('/b').edges.t.tolist() == [1, 2]
    from evsync_ros.errors import StreamError
    with pytest.raises(StreamError):
        feed.add_edges(e, '/c', np.array([1], np.int64), np.array([1], np.uint8))


def test_trigger_channels_are_checked():
    values = {**node_defaults(), 'topics': ['/a/events', '/b/events'], 'types': ['event_camera_msgs/msg/EventPacket']}
    assert node_config({**values, 'trigger_channels': ['/a/events=0', '/b/events=3']}).trigger_channels == {
        '/a/events': 0, '/b/events': 3}
    for bad in (['/c/events=0'], ['/a/events'], ['/a/events=x']):
        with pytest.raises(ParameterError, match='trigger_channels'):
            node_config({**values, 'trigger_channels': bad})
    with pytest.raises(ParameterError, match='processes: one'):
        node_config({**values, 'trigger_channels': ['/a/events=0'], 'processes': 'per_camera'})
