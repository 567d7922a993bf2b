"""What estimate_bag reads from when the messages arrived: where to search for a camera that began
recording seconds after the others, or where the live node would, and whether a camera's clock
jumped during the recording (simulated rigs, and real recordings' virtual rigs, written as rosbag2
files)."""

import json
import re
from dataclasses import replace

import numpy as np
import pytest

from evsync_ros.bag.estimate import estimate_bag, read_event_times
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.writer import BagWriter
from evsync_ros.cli import main as cli
from evsync_ros.errors import StreamError
from evsync_ros.sim.pixelsim import preset, simulate
from evsync_ros.sim.simbag import error_ns, write_rig
from evsync_testing.realcases import front_cases
from evsync_testing.realdata import read_events
from evsync_testing.virtual import Case
from evsync_testing.virtualbag import write_bag
from msg_adapters.cdr import read_stamp, write_stamp

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


def test_a_camera_that_began_seconds_late_is_found_where_its_arrival_times_put_it(late_rig):
    """Its first events put it 7 s off, past a 5 s search: the engine searches where its messages'
    arrival times put it, as the live node does."""
    bag, truth = late_rig
    est = estimate_bag(bag)
    for topic, (accepted, err, se) in errors(est, bag, truth).items():
        assert accepted and abs(err) < 100_000 and abs(err) < 3 * se, (topic, err, se)
    assert cli.main(['estimate', str(bag)]) == 0


def test_arrival_times_that_mislead_leave_the_camera_not_accepted_saying_where_it_was_searched(late_rig, tmp_path):
    """The late camera's messages recorded a minute late: not within reach of where they put it."""
    bag, _ = late_rig
    moved = tmp_path / 'moved'
    with BagReader(bag) as reader, BagWriter(moved) as writer:
        conns = {c.topic: writer.add_topic(c.topic, c.msgtype) for c in reader.connections}
        for conn, stamp, raw in reader.messages():
            writer.write(conns[conn.topic], stamp + (60 * S if conn.topic == LATE else 0), bytes(raw))
    fit = estimate_bag(moved).rig.camera(LATE)
    assert not fit.accepted
    where = re.search(r'searched within 0\.5 s of where its arrival times put it, ([-+0-9.]+) s from', fit.reason)
    assert where and 60 < float(where.group(1)) < 68, fit.reason  # the minute and the 7 s late start


def test_the_consistency_check_keeps_the_bag_s_estimate(late_rig, capsys):
    """--consistency adds the pair check to the streamed estimate: before, it estimated from the event
    times alone, without the arrival times, and /cam1 came out "windows disagree"."""
    bag, _ = late_rig
    plain = estimate_bag(bag)
    est = estimate_bag(bag, consistency=True)
    assert est.rig.as_json() == plain.rig.as_json()  # every camera's estimate as without the check
    (pair, residual), = est.rig.pair_residual_ns.items()
    assert set(pair) == {LATE, '/cam2/events'} and abs(residual) < 100_000, est.rig.pair_residual_ns
    assert cli.main(['estimate', '--consistency', str(bag)]) == 0
    assert 'consistency over 1 camera pairs: largest disagreement' in capsys.readouterr().out


def test_a_camera_a_wide_search_cannot_place_is_placed_where_the_live_node_searches(real_data, tmp_path):
    """The real EVK4's left and right halves (the second stopping 0.5 s early and starting 0.1 s late),
    as evt3 at a packet a millisecond: over +-5 s the windows peak apart (different parts of the
    scene), but within 0.5 s of where the arrival times put the camera, where the live node searches,
    they agree on the truth; the node locks there (studies/live_real.py)."""
    (events,) = read_events(real_data / 'evk4_hd').values()
    bag = tmp_path / 'halves'
    truth = write_bag(Case('t', 'halves', 'evk4_hd', 'halves', offset_ns=3_987_000_123, seed=104,
                           early_ns=500_000_000, late_ns=100_000_000), events, bag)
    est = estimate_bag(bag)
    fit = est.rig.camera(truth['cameras'][1]['topic'])
    assert fit.accepted, fit.reason
    ((_, err, se),) = errors(est, bag, truth).values()
    assert abs(err) < 100_000 and abs(err) < 3 * se, (err, se)
    assert cli.main(['estimate', str(bag)]) == 0


@pytest.mark.parametrize('name', ['parity motion 1 s', 'random motion 3 s'])
def test_motion_in_one_stretch_is_accepted_from_the_bag(real_data, tmp_path, name):
    """Issue 38: the real EVK4 split whose scene moves only in its first 1 or 3 s of 10.8, as a host
    records it (``bench/realrigs.py --only front``): accepted within 0.1 ms or 3 stated errors (issue
    38's target). Before, the 1 s one was refused as "could be chance": a faint window landing on the
    line by chance within its millisecond error joined the one loud window; now faint windows are no
    evidence, and the stretch of motion is decided on its own shorter windows. (The 3 s one was
    accepted before too, 0.28 ms off at a stated 0.70 ms: a quiet window on its line still counts.)"""
    (events,) = read_events(real_data / 'evk4_hd').values()
    (case,) = [c for c in front_cases(False) if c.name.startswith(name)]
    truth = write_bag(case, events, tmp_path / 'front')
    est = estimate_bag(tmp_path / 'front')
    fit = est.rig.camera(truth['cameras'][1]['topic'])
    assert fit.accepted, fit.reason
    ((_, err, se),) = errors(est, tmp_path / 'front', truth).values()
    assert abs(err) < max(100_000, 3 * se), (err, se)


@pytest.fixture(scope='module')
def jumped_rig(tmp_path_factory):
    """Three same-model cameras over 20 s, /cam1's clock jumping 50 ms on at 17.5 s: after it, one window
    (of 9) is left, too few for the windows alone to tell a jump from a stray window."""
    d = tmp_path_factory.mktemp('jumped')
    rig = preset('same-model', seed=0, duration_s=20)
    cams = [replace(c, clock_step=(17_500_000_000, 50_000_000)) if c.topic == LATE else c for c in rig.cameras]
    rig = replace(rig, cameras=tuple(cams))
    return d / 'rig', write_rig(rig, simulate(rig), d / 'rig')


def test_a_camera_whose_clock_jumped_is_not_accepted_by_what_its_arrival_times_say(jumped_rig):
    bag, truth = jumped_rig
    est = estimate_bag(bag)
    fit = est.rig.camera(LATE)
    assert not fit.accepted and fit.uncertainty_ns is None
    assert fit.reason.startswith("clock step: its arrival times say its clock jumped by +50.0 ms against the "
                                 "reference's about 1"), fit.reason  # the windows alone accepted it
    assert errors(est, bag, truth)['/cam2/events'][0]  # the others are as they were


def test_with_the_consistency_check_a_camera_whose_clock_jumped_is_still_not_accepted(jumped_rig, capsys):
    bag, _ = jumped_rig
    assert cli.main(['estimate', '--consistency', '--json', str(bag)]) == 1
    doc = json.loads(capsys.readouterr().out)
    (cam,) = [c for c in doc['cameras'] if c['topic'] == LATE]
    assert not cam['accepted'] and cam['reason'].startswith('clock step: its arrival times say'), cam['reason']
    assert cli.main(['estimate', '--consistency', str(bag)]) == 1
    assert 'consistency: no camera pair to check (1 accepted camera(s) besides the reference' in \
        capsys.readouterr().out


@pytest.fixture(scope='module')
def dvs_rig(tmp_path_factory):
    """Three same-model cameras over 20 s, each sending dvs_msgs/EventArray stamped with its own clock:
    the host's clock is in the record times only."""
    d = tmp_path_factory.mktemp('dvs')
    rig = preset('same-model', seed=0, duration_s=20)
    rig = replace(rig, cameras=tuple(replace(c, encoding='dvs') for c in rig.cameras))
    return d / 'rig', write_rig(rig, simulate(rig), d / 'rig')


def test_a_jump_of_the_host_clock_is_no_camera_s_jump(dvs_rig, tmp_path):
    """Every message from 12 s on recorded 3 s later, the host's clock having stepped (NTP); a header
    stamp read as the host's (within 1 s of the record time: /cam0's clock starts at the host's) steps
    with it. The events, which carry their own times, do not move."""
    bag, truth = dvs_rig
    stepped = tmp_path / 'host_stepped'
    with BagReader(bag) as reader, BagWriter(stepped) as writer:
        conns = {c.topic: writer.add_topic(c.topic, c.msgtype) for c in reader.connections}
        start = reader.start_ns
        for conn, stamp, raw in reader.messages():
            if stamp - start >= 12 * S:
                out = bytearray(raw)
                if abs(read_stamp(raw) - stamp) < S:
                    write_stamp(out, read_stamp(raw) + 3 * S, conn.topic)
                stamp, raw = stamp + 3 * S, bytes(out)
            writer.write(conns[conn.topic], stamp, raw)
    est = estimate_bag(stepped)
    for topic, (accepted, err, se) in errors(est, stepped, truth).items():
        assert accepted and abs(err) < 3 * se, (topic, est.rig.camera(topic).reason)


def test_a_drifting_camera_is_read_again_with_the_reference_only(tmp_path):
    # the second read bins the drifting camera through its skew against the reference; the other
    # cameras' messages are not read again (progress counts what each read reads)
    rig = preset('same-model', seed=0, duration_s=20)
    drifting = rig.cameras[2].topic
    rig = replace(rig, cameras=tuple(replace(c, skew_ppm=40.0) if c.topic == drifting else c for c in rig.cameras))
    bag = tmp_path / 'rig'
    truth = write_rig(rig, simulate(rig), bag)
    ticks = []
    est = estimate_bag(bag, reference=rig.reference, progress=lambda done, total: ticks.append((done, total)))
    with BagReader(bag) as reader:
        counts = reader.message_counts()
    assert est.passes == 2 and set(est.binned) == {drifting}
    assert ticks[-1] == (sum(counts.values()) + counts[rig.reference] + counts[drifting],) * 2
    accepted, error, se = errors(est, bag, truth)[drifting]
    assert accepted and abs(error) < 3 * se + 100_000


@pytest.mark.parametrize('method', ['refined', 'paper'])
@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_a_camera_with_no_decodable_message_is_an_error_saying_what_was_read(tmp_path, method, storage):
    """Every message of /cam1 cut short: the error names it, how many messages were read and
    undecodable, and the first reason, with either method (read in one process or two)."""
    from evsync_testing.messages import evt3_packets
    from msg_adapters.definitions import EVENT_PACKET

    good, bad = evt3_packets(300), evt3_packets(300, start_us=9_000)
    with BagWriter(tmp_path / 'in', storage=storage) as writer:
        cam0 = writer.add_topic('/cam0/events', EVENT_PACKET)
        cam1 = writer.add_topic('/cam1/events', EVENT_PACKET)
        for i, (a, b) in enumerate(zip(good, bad)):
            writer.write(cam0, 1_700_000_000 * 10**9 + i * 10**6, a)
            writer.write(cam1, 1_700_000_000 * 10**9 + i * 10**6 + 1, b[:40])
    with pytest.raises(StreamError, match=r'no decodable events on /cam1/events \(/cam1/events: 300 messages, '
                                          r'300 undecodable \(first: .+\)\)'):
        estimate_bag(tmp_path / 'in', method=method)
