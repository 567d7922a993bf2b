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


@pytest.fixture(scope='module')
def unwired_reference(tmp_path_factory):
    """mixed-models' three cameras, all evt3, 20 s, a 5 Hz pulse on channel 0; the reference's edges
    are in its stream but not read (its channel not given): as to the engine, it has none."""
    rig = preset('mixed-models', seed=3, duration_s=20, triggers_hz=5)
    rig = replace(rig, cameras=(rig.cameras[0], replace(rig.cameras[1], encoding='evt3'), rig.cameras[2]))
    bag = tmp_path_factory.mktemp('unwired') / 'rig'
    return bag, write_rig(rig, simulate(rig), bag)


def between(a: paths.Verdict, b: paths.Verdict, truth: dict) -> float:
    """How far ``a`` and ``b`` put one instant apart on the reference's timeline (ns): the difference
    of their errors against the truth (whose own reference cancels), each at its camera's time of one
    instant."""
    def error(v: paths.Verdict, at_ref: int) -> float:
        t = next(c for c in truth['cameras'] if c['topic'] == v.topic)
        true = ClockCorrection(offset_ns=t['offset_ns'], skew_ppm=t['skew_ppm'], anchor_ns=t['anchor_ns'])
        assert v.offset_ns is not None
        mine = ClockCorrection(offset_ns=v.offset_ns, skew_ppm=v.skew_ppm, anchor_ns=v.anchor_ns)
        at = at_ref - t['offset_ns']  # the camera's time of it, to its skew's microseconds a second
        return mine.apply_one(at) - true.apply_one(at)
    return error(a, a.anchor_ns + a.offset_ns) - error(b, a.anchor_ns + a.offset_ns)


def test_two_cameras_are_tied_edge_to_edge_when_the_reference_has_none(unwired_reference):
    """Item 4's last part: the Prophesee-like and the DVXplorer-like camera both read their edges,
    the reference (DAVIS-like) does not; the two are tied to each other within 10 us, where their
    density decisions alone put them tens of microseconds apart (the makes' lag)."""
    bag, truth = unwired_reference
    p, x = '/prophesee/events', '/dvxplorer/events'
    run = paths.through_node(bag, reference='/davis/events', extra={'trigger_channels': [f'{p}=0', f'{x}=0']})
    vp, vx = run.verdicts[p], run.verdicts[x]
    assert vp.accepted and vx.accepted, (vp, vx)
    said = run.reports[-1][1]
    tied = [t for t in (p, x) if said[t]['trigger_tied_to']]
    assert len(tied) == 1 and said[tied[0]]['trigger_tied_to'] == ({p, x} - set(tied)).pop(), said
    assert int(said[tied[0]]['trigger_edges']) > 50
    apart = between(vp, vx, truth)
    alone = float(said[tied[0]]['density_minus_edges_us']) * 1e3
    print(f'{p} and {x}: {apart / 1e3:+.2f} us apart tied, the density decision {alone / 1e3:+.1f} us from the tie')
    assert abs(apart) <= 10_000, apart
    assert abs(alone) > 30_000  # the tie moved it by the makes' lag, which the density alone carries


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
