"""estimate_bag's search for a camera that began recording seconds after the others: where its arrival
times put it, when its first events put it out of reach (simulated rigs written as rosbag2 files)."""

from dataclasses import replace

import numpy as np
import pytest

from evsync_ros.bag.estimate import estimate_bag, read_event_times
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.writer import BagWriter
from evsync_ros.cli import main as cli
from evsync_ros.core.refined import RefinedParams
from evsync_ros.sim.pixelsim import preset, simulate
from evsync_ros.sim.simbag import error_ns, write_rig

S = 1_000_000_000
LATE = '/cam1/events'


@pytest.fixture(scope='module')
def late_rig(tmp_path_factory):
    """Three same-model cameras over 20 s, /cam1 streaming from 7 s on (the others within 1.5 s of the
    start): its first events put its offset 7 s off, past the 5 s search."""
    d = tmp_path_factory.mktemp('late')
    rig = preset('same-model', seed=0, duration_s=20)
    cams = [replace(c, start_ns=7 * S) if c.topic == LATE else c for c in rig.cameras]
    rig = replace(rig, cameras=tuple(cams))
    return d / 'rig', write_rig(rig, simulate(rig), d / 'rig')


def errors(est, bag, truth):
    """Per camera: (accepted, error at the middle of its recording, its standard error there)."""
    times, _ = read_event_times(bag)
    out = {}
    for cam in truth['cameras'][1:]:
        fit = est.rig.camera(cam['topic'])
        mid = int(np.median(times[cam['topic']]))
        out[cam['topic']] = (fit.accepted, error_ns(fit.as_json(), cam, mid), fit.uncertainty_at(mid))
    return out


def test_a_camera_that_began_seconds_late_is_found_where_its_arrival_times_put_it(late_rig, capsys):
    bag, truth = late_rig
    est = estimate_bag(bag)
    first, arrival = est.arrival_priors[LATE]
    assert abs(arrival - first) > RefinedParams().max_shift_ns  # out of the first search's reach
    assert set(est.arrival_priors) == {LATE}  # the camera found where its first events put it is not searched again
    assert est.passes == 2
    for topic, (accepted, err, se) in errors(est, bag, truth).items():
        assert accepted and abs(err) < 100_000 and abs(err) < 3 * se, (topic, err, se)
    assert cli.main(['estimate', str(bag)]) == 0
    assert (f'{LATE}: not found within 5 s of the offset its first events give; searched again around the one '
            'its arrival times give') in capsys.readouterr().err


def test_arrival_times_that_mislead_too_leave_the_camera_not_accepted_saying_both(late_rig, tmp_path):
    """The late camera's messages recorded a minute late: neither search has it within reach."""
    bag, _ = late_rig
    moved = tmp_path / 'moved'
    with BagReader(bag) as reader, BagWriter(moved) as writer:
        conns = {c.topic: writer.add_topic(c.topic, c.msgtype) for c in reader.connections}
        for conn, stamp, raw in reader.messages():
            writer.write(conns[conn.topic], stamp + (60 * S if conn.topic == LATE else 0), bytes(raw))
    est = estimate_bag(moved)
    fit = est.rig.camera(LATE)
    assert not fit.accepted
    assert 'nor around where its arrival times put it' in fit.reason, fit.reason
    first, arrival = est.arrival_priors[LATE]
    assert abs(arrival - first - 67 * S) < S  # the 7 s late start and the minute
