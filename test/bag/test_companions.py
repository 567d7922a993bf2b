"""Companion topics offline: a camera's IMU (and any topic whose type begins with a std_msgs/Header)
restamped with that camera's correction, header.stamp only, every other byte kept."""

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from evsync_ros.bag.estimate import estimate_bag
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.bag.writer import BagWriter
from evsync_ros.cli import main as cli
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.errors import BagError
from evsync_ros.sim.pixelsim import preset, simulate
from evsync_ros.sim.simbag import write_rig
from msg_adapters.cdr import read_stamp

STRING = 'std_msgs/msg/String'


@pytest.fixture(scope='module')
def imu_rig(tmp_path_factory):
    """A mixed-models rig, each camera with a 200 Hz IMU on its own clock, and a text topic."""
    d = tmp_path_factory.mktemp('companions')
    rig = preset('mixed-models', seed=2, duration_s=12)
    truth = write_rig(rig, simulate(rig, imu_hz=200.0), d / 'sim')
    store = get_typestore(Stores.ROS2_JAZZY)
    with BagReader(d / 'sim') as reader, BagWriter(d / 'rig', storage='mcap') as writer:
        conns = {c.topic: writer.add_topic(c.topic, c.msgtype, msgdef=c.msgdef.data, rihs01=c.digest)
                 for c in reader.connections}
        notes = writer.add_topic('/notes', STRING)
        for i, (conn, t, raw) in enumerate(reader.messages()):
            writer.write(conns[conn.topic], t, raw)
            if i % 500 == 0:
                writer.write(notes, t, bytes(store.serialize_cdr(store.types[STRING](data=f'{i}'), STRING)))
    return d / 'rig', truth


def by_topic(bag):
    out: dict[str, list[tuple[int, bytes]]] = {}
    with BagReader(bag) as reader:
        for conn, t, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t, bytes(raw)))
    return out


def truth_map(cam):
    return ClockCorrection(offset_ns=cam['offset_ns'], skew_ppm=cam['skew_ppm'], anchor_ns=cam['anchor_ns'])


def test_each_imu_moves_with_its_camera_stamp_only(imu_rig, tmp_path):
    bag, truth = imu_rig
    est = estimate_bag(bag, reference=truth['reference'])
    companions = {c['imu_topic']: c['topic'] for c in truth['cameras']}
    rep = restamp_bag(bag, tmp_path / 'out', corrections=est.rig.corrections, reference=truth['reference'],
                      companions=companions)
    assert rep.bad == 0
    before, after = by_topic(bag), by_topic(tmp_path / 'out')
    assert after['/notes'] == before['/notes']
    for cam in truth['cameras']:
        imu = cam['imu_topic']
        fit = est.rig.camera(cam['topic'])
        assert len(after[imu]) == len(before[imu]) == rep.topics[imu].messages_out > 2000
        if cam['topic'] == truth['reference']:
            assert after[imu] == before[imu] and rep.topics[imu].restamped == 0
            continue
        assert rep.topics[imu].restamped == len(before[imu])
        worst = 0
        for (t0, a), (t1, b) in zip(before[imu], after[imu]):
            assert a[:4] == b[:4] and a[12:] == b[12:]  # every byte but the stamp
            assert read_stamp(b) == fit.correction.apply_one(read_stamp(a))
            worst = max(worst, abs(read_stamp(b) - truth_map(cam).apply_one(read_stamp(a))))
            # the record time moves with the stamp exactly when the camera's own messages' does
            assert (t1 - t0 == read_stamp(b) - read_stamp(a)) if rep.topics[imu].record_shifted else t1 == t0
        assert worst <= 3 * fit.uncertainty_ns  # as close to the truth as the camera's own estimate says
        # and the camera's events were restamped with the very same correction
        assert rep.topics[cam['topic']].restamped == len(before[cam['topic']])


def test_imu_and_events_stay_together_in_a_ros1_output(imu_rig, tmp_path):
    bag, truth = imu_rig
    corrections = {c['topic']: truth_map(c) for c in truth['cameras']}
    companions = {c['imu_topic']: c['topic'] for c in truth['cameras']}
    restamp_bag(bag, tmp_path / 'out.bag', corrections=corrections, reference=truth['reference'],
                companions=companions)
    before, after = by_topic(bag), by_topic(tmp_path / 'out.bag')
    for cam in truth['cameras']:
        stamps = np.array([read_stamp(r) for _, r in before[cam['imu_topic']]])
        moved = np.array([read_stamp(r) for _, r in after[cam['imu_topic']]])
        np.testing.assert_array_equal(moved, truth_map(cam).apply(stamps))


@pytest.mark.parametrize(('companions', 'match'), [
    ({'/notes': '/davis/events'}, r'/notes has type std_msgs/msg/String, which does not begin with a std_msgs/Header'),
    ({'/nope/imu': '/davis/events'}, r'no companion topic /nope/imu'),
    ({'/davis/imu': '/nope/events'}, r'/davis/imu names /nope/events, which is not an event topic'),
    ({'/davis/events': '/prophesee/events'}, r'/davis/events is an event topic'),
])
def test_companions_that_cannot_be_are_refused_by_name(imu_rig, tmp_path, companions, match):
    bag, truth = imu_rig
    corrections = {c['topic']: truth_map(c) for c in truth['cameras']}
    with pytest.raises(BagError, match=match):
        restamp_bag(bag, tmp_path / 'out', corrections=corrections, reference=truth['reference'],
                    companions=companions)
    assert not (tmp_path / 'out').exists()


def test_cli_companion_option(imu_rig, tmp_path, capsys):
    bag, truth = imu_rig
    argv = ['restamp', str(bag), str(tmp_path / 'out'), '--reference', truth['reference']]
    assert cli.main([*argv, '--companion', '/davis/imu']) == 2
    assert 'TOPIC=EVENT_TOPIC' in capsys.readouterr().err
    pairs = [x for c in truth['cameras'] for x in ('--companion', f'{c["imu_topic"]}={c["topic"]}')]
    assert cli.main([*argv, *pairs]) == 0
    out = capsys.readouterr().out
    davis = next(line for line in out.splitlines() if line.startswith('/davis/imu '))
    assert 'sensor_msgs/msg/Imu' in davis and int(davis.split()[3].replace(',', '')) > 2000  # restamped
    # with offsets saved by estimate --json too
    assert cli.main(['estimate', str(bag), '--reference', truth['reference'], '--json']) == 0
    (tmp_path / 'est.json').write_text(capsys.readouterr().out)
    assert cli.main(['restamp', str(bag), str(tmp_path / 'out2'), '--offsets', str(tmp_path / 'est.json'),
                     *pairs]) == 0
    assert by_topic(tmp_path / 'out2')['/davis/imu'] == by_topic(tmp_path / 'out')['/davis/imu']
