"""--start and --duration (issue 24): estimate, report and restamp estimate from a stretch of the bag
only, in rosbag2 and ROS 1 bags alike; a stretch outside the bag is refused by name."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from evsync_ros.bag.estimate import estimate_bag, read_event_times
from evsync_ros.bag.reader import BagReader
from evsync_ros.cli.main import main
from evsync_ros.sim.simbag import error_ns

S = 1_000_000_000


@pytest.fixture(scope='module', params=['rig', 'rig.bag'], ids=['rosbag2', 'ros1'])
def rig(request, tmp_path_factory) -> tuple[Path, dict]:
    bag = tmp_path_factory.mktemp('windows') / request.param
    assert main(['simulate', str(bag), '--preset', 'same-model', '--duration', '16']) == 0
    truth = json.loads(bag.with_name(bag.name + '.truth.json').read_text())
    return bag, truth


def recorded_in(bag: Path, start_s: float, duration_s: float) -> dict[str, int]:
    """Messages per topic whose record time lies in the stretch, counted here without the window."""
    with BagReader(bag) as reader:
        first = reader.start_ns
        lo, hi = first + round(start_s * S), first + round((start_s + duration_s) * S)
        counts: dict[str, int] = {}
        for conn, t, _ in reader.messages():
            if lo <= t < hi:
                counts[conn.topic] = counts.get(conn.topic, 0) + 1
    return counts


def test_an_estimate_reads_only_the_stretch_asked_for_and_is_right(rig):
    bag, truth = rig
    est = estimate_bag(bag, reference=truth['reference'], start_s=4.0, duration_s=9.0)
    expected = recorded_in(bag, 4.0, 9.0)
    whole = estimate_bag(bag, reference=truth['reference'])
    for topic, rep in est.reports.items():
        assert rep.messages == expected[topic], topic
        assert rep.messages < whole.reports[topic].messages
    by_topic = {c['topic']: c for c in truth['cameras']}
    for cam in est.rig.cameras:
        assert cam.accepted, cam
        fit = json.loads(json.dumps(est.rig.as_json()))['cameras']
        one = next(c for c in fit if c['topic'] == cam.topic)
        assert abs(error_ns(one, by_topic[cam.topic], by_topic[cam.topic]['anchor_ns'] + 8 * S)) < 500_000
    times, _ = read_event_times(bag, start_s=4.0, duration_s=9.0)
    all_times, _ = read_event_times(bag)
    for topic in times:  # the stretch's events are a middle part of each camera's
        assert 0 < times[topic].size < all_times[topic].size
        assert times[topic][0] > all_times[topic][0] and times[topic][-1] < all_times[topic][-1]


def test_the_commands_take_start_and_duration(rig, tmp_path, capsys):
    bag, truth = rig
    ref = truth['reference']
    assert main(['estimate', str(bag), '--reference', ref, '--start', '4', '--duration', '9']) == 0
    assert 'from 4 s for 9 s' in capsys.readouterr().out
    assert main(['report', str(bag), '--reference', ref, '--start', '4']) == 0
    assert 'from 4 s on' in capsys.readouterr().out
    out = tmp_path / ('out.bag' if bag.suffix == '.bag' else 'out')
    assert main(['restamp', str(bag), str(out), '--reference', ref, '--start', '2', '--duration', '10']) == 0
    with BagReader(bag) as a, BagReader(out) as b:  # the whole bag restamped, not the stretch
        assert a.message_counts() == b.message_counts()


@pytest.mark.parametrize(('argv', 'said'), [
    (['--start', '100'], "past the bag's end"),
    (['--start', '-1'], '--start must be >= 0'),
    (['--duration', '0'], '--duration > 0'),
])
def test_a_stretch_outside_the_bag_is_refused_by_name(rig, capsys, argv, said):
    bag, truth = rig
    assert main(['estimate', str(bag), '--reference', truth['reference'], *argv]) == 2
    err = capsys.readouterr().err
    assert said in err and str(bag) in err


def test_start_is_refused_where_nothing_is_estimated(rig, tmp_path, capsys):
    bag, truth = rig
    offsets = tmp_path / 'est.json'
    assert main(['estimate', str(bag), '--json', '--reference', truth['reference']]) == 0
    offsets.write_text(capsys.readouterr().out)
    assert main(['restamp', str(bag), str(tmp_path / 'o'), '--offsets', str(offsets), '--start', '3']) == 2
    assert 'with --offsets nothing is estimated' in capsys.readouterr().err
    assert not (tmp_path / 'o').exists()
    assert main(['report', str(offsets), '--duration', '3']) == 2
    assert 'are for bags' in capsys.readouterr().err
