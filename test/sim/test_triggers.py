"""Simulated trigger-in: a pulse train at true times, each camera stamping it on its own clock, written
where its driver would send it; decoded back through the adapters, against the truth JSON."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from evsync_ros.bag.reader import BagReader
from evsync_ros.cli.main import main
from evsync_ros.errors import ParameterError
from evsync_ros.sim.pixelsim import parse_make, preset, simulate
from evsync_ros.sim.simbag import write_rig
from evsync_ros.sim.triggers import TriggerTrain, stamp_edges, train_edges
from msg_adapters.registry import stream_edges

NS = 1_000_000_000


def two_make_rig():
    """Two makes of different lag (make B: threshold 0.30, a 1 ms photoreceptor, written as dvs), make
    B's clock 40 ppm fast, a 5 Hz train that each camera misses one edge in ten of."""
    rig = preset('two-makes-fast', seed=4, duration_s=6, make=parse_make('lowpass-us=1000'), triggers_hz=5)
    cams = (rig.cameras[0], replace(rig.cameras[1], skew_ppm=40.0))
    return replace(rig, cameras=cams, triggers=TriggerTrain(hz=5, duty=0.3, jitter_ns=2_000, miss_rate=0.1, channel=3))


@pytest.fixture(scope='module')
def rig_events():
    rig = two_make_rig()
    return rig, simulate(rig)


def decoded_edges(bag) -> dict:
    streams: dict[str, tuple[str, list[bytes]]] = {}
    with BagReader(bag) as reader:
        for conn, _, raw in reader.messages():
            streams.setdefault(conn.topic, (conn.msgtype, []))[1].append(bytes(raw))
    return {topic: stream_edges(raws, msgtype) for topic, (msgtype, raws) in streams.items()}


def test_each_camera_decodes_its_edges_where_the_truth_puts_them(tmp_path, rig_events):
    rig, events = rig_events
    truth = write_rig(rig, events, tmp_path / 'bag')
    assert json.loads((tmp_path / 'bag.truth.json').read_text()) == truth
    train = truth['triggers']
    assert (train['hz'], train['duty'], train['jitter_ns'], train['channel']) == (5, 0.3, 2_000, 3)
    true_ns, value = train_edges(rig.triggers, rig.scene.duration_ns)
    assert (train['true_ns'], train['value']) == (true_ns.tolist(), value.tolist())
    got = decoded_edges(tmp_path / 'bag')
    assert {c['topic']: c['triggers']['topic'] for c in truth['cameras']} == {
        '/make_a/events': '/make_a/events', '/make_b/events': '/make_b/trigger'}
    for cam in truth['cameras']:
        mine = cam['triggers']
        stream = got[mine['topic']]
        edges = stream.edges
        assert (stream.undecodable, dict(stream.anomalies)) == (0, {}), cam['topic']
        assert len(edges) == len(mine['index']) == len(mine['times_ns']) > 20
        assert set(edges.channel.tolist()) == {3}
        np.testing.assert_array_equal(edges.value, value[mine['index']])
        error = edges.t - np.array(mine['times_ns'])
        # the jitter, and evt3's microsecond time words (sensor time floored to the microsecond)
        low = -2_000 - (1_000 if mine['encoding'] == 'evt3' else 0)
        assert low <= error.min() and error.max() <= 2_000, cam['topic']
        assert error.std() > 500  # the jitter is there
        # the missed edges are missing: no decoded edge near where they would be
        assert mine['missed'] and not set(mine['missed']) & set(mine['index'])
        would_be = np.array(mine['times_ns'])[0] + (true_ns[mine['missed']] - true_ns[mine['index'][0]])
        assert np.abs(edges.t[:, None] - would_be[None, :]).min() > 10_000_000
        # every edge of the train from the camera's first one on is recorded or missed
        assert sorted(mine['index'] + mine['missed']) == list(range(mine['index'][0], true_ns.size))


def test_the_events_and_their_bag_are_the_same_with_or_without_triggers(tmp_path, rig_events):
    rig, with_triggers = rig_events
    without = simulate(replace(rig, triggers=None))
    for topic, ev in without.items():
        assert ev.triggers is None and with_triggers[topic].triggers is not None
        for f in 'txyp':
            np.testing.assert_array_equal(getattr(with_triggers[topic], f), getattr(ev, f))
    truth_with = write_rig(rig, with_triggers, tmp_path / 'with')
    truth_without = write_rig(replace(rig, triggers=None), without, tmp_path / 'without')
    assert 'triggers' not in truth_without
    for a, b in zip(truth_with['cameras'], truth_without['cameras']):
        assert {k: v for k, v in a.items() if k != 'triggers'} == b
    stamps: dict[str, list[list[int]]] = {}
    for name in ('with', 'without'):
        with BagReader(tmp_path / name) as reader:
            for conn, stamp, _ in reader.messages():
                stamps.setdefault(conn.topic, [[], []])[name == 'without'].append(stamp)
    assert set(stamps) == {'/make_a/events', '/make_b/events', '/make_b/trigger'}
    assert stamps['/make_b/events'][0] == stamps['/make_b/events'][1]  # the dvs camera's messages as they were
    assert len(stamps['/make_a/events'][0]) == len(stamps['/make_a/events'][1])  # evt3: the same messages


def test_train_edges_rise_each_period_and_fall_duty_later():
    train = TriggerTrain(hz=4, duty=0.25, phase_ns=50_000_000)
    t, value = train_edges(train, 1_000_000_000)
    assert t.tolist() == [50_000_000, 112_500_000, 300_000_000, 362_500_000, 550_000_000, 612_500_000,
                          800_000_000, 862_500_000]
    assert value.tolist() == [1, 0] * 4
    t, value = train_edges(train, 830_000_000)  # a pulse cut by the end
    assert (t[-1], value[-1]) == (800_000_000, 1)


def test_stamps_are_jittered_within_the_bound_and_missed_at_the_rate():
    train = TriggerTrain(hz=1_000, duty=0.5, jitter_ns=1_000, miss_rate=0.2)
    true_ns, value = train_edges(train, 20 * NS)
    stamps = stamp_edges(train, true_ns, value, from_ns=NS, clock=lambda t: t + 7, rng=np.random.default_rng(0))
    inside = np.flatnonzero(true_ns >= NS)
    assert np.array_equal(np.sort(np.concatenate([stamps.index, stamps.missed])), inside)
    assert abs(stamps.missed.size / inside.size - 0.2) < 0.01
    jitter = stamps.t - 7 - true_ns[stamps.index]
    assert jitter.min() == -1_000 and jitter.max() == 1_000
    assert np.array_equal(stamps.true_t, true_ns[stamps.index]) and np.array_equal(stamps.value, value[stamps.index])


@pytest.mark.parametrize('kwargs', [{'hz': 0}, {'duty': 1.0}, {'miss_rate': 1.0}, {'channel': 16},
                                    {'jitter_ns': -1}, {'hz': 1e6, 'jitter_ns': 1_000}])
def test_a_train_that_cannot_be_is_refused(kwargs):
    with pytest.raises(ParameterError, match='trigger train'):
        TriggerTrain(**kwargs)


def test_simulate_triggers_option(tmp_path, capsys):
    bag = tmp_path / 'rig'
    assert main(['simulate', str(bag), '--preset', 'mixed-models', '--duration', '3', '--triggers', '2']) == 0
    truth = json.loads((tmp_path / 'rig.truth.json').read_text())
    assert truth['triggers']['hz'] == 2
    got = decoded_edges(bag)
    for cam in truth['cameras']:
        assert len(got[cam['triggers']['topic']].edges) == len(cam['triggers']['index']) > 0
    with pytest.raises(ParameterError, match='triggers_hz'):
        preset('same-model', triggers_hz=-1)


def test_a_trigger_topic_is_no_camera_and_moves_with_its_camera(tmp_path, rig_events, capsys):
    """A dvs camera's edges on a topic of their own (EventPacket ``trigger``): the estimate does not
    take it for a camera (it has no events), and restamp moves it with its camera, so that after
    restamping both cameras' edges of one pulse sit together on the reference's timeline."""
    rig, events = rig_events
    write_rig(rig, events, tmp_path / 'bag')
    assert main(['estimate', str(tmp_path / 'bag'), '--json']) == 0
    est = json.loads(capsys.readouterr().out)
    assert sorted(c['topic'] for c in est['cameras']) == ['/make_a/events', '/make_b/events']
    assert main(['restamp', str(tmp_path / 'bag'), str(tmp_path / 'out'), '--force']) == 0
    got = decoded_edges(tmp_path / 'out')
    a, b = got['/make_a/events'].edges, got['/make_b/trigger'].edges
    assert len(a) > 20 and len(b) > 20
    gap = np.abs(b.t[:, None] - a.t[None, :]).min(axis=1)  # each of b's edges to a's nearest
    # an edge's jitter (2 us each), evt3's microsecond, and the estimate's error (its se within 1 ms)
    assert np.median(gap) < 1_000_000, np.median(gap)
    # before restamping, the two cameras' edges were apart by their clocks' offset
    before = decoded_edges(tmp_path / 'bag')
    far = np.abs(before['/make_b/trigger'].edges.t[:, None] - before['/make_a/events'].edges.t[None, :]).min(axis=1)
    assert np.median(far) > 10_000_000


def test_a_trigger_topic_named_as_a_camera_is_refused(tmp_path, rig_events, capsys):
    rig, events = rig_events
    write_rig(rig, events, tmp_path / 'bag')
    assert main(['estimate', str(tmp_path / 'bag'), '--topics', '/make_a/events', '/make_b/trigger']) != 0
    assert 'carries trigger edges' in capsys.readouterr().err
