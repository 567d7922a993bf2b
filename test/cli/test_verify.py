"""evsync verify BAG: the density estimate against the trigger edges every camera recorded of one
pulse, on a simulated two-make rig (whose truth is known: a simulator-only check) and on two copies
of the real evt3 recording, whose only edges are its 1 kHz loopback."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from evsync_ros.cli import main as cli
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.sim.pixelsim import parse_make, preset, simulate
from evsync_ros.sim.simbag import write_rig
from evsync_ros.sim.triggers import TriggerTrain
from evsync_testing.origins import merged_copies


@pytest.fixture(scope='module')
def two_makes(tmp_path_factory):
    """Make A (evt3, edges in its events) and make B (dvs, 1 ms photoreceptor, its edges on
    /make_b/trigger, its clock 40 ppm slow), 16 s, a 5 Hz pulse with 2 us jitter, an edge in ten
    missed by each camera."""
    rig = preset('two-makes-fast', seed=4, duration_s=16, make=parse_make('lowpass-us=1000'), triggers_hz=5)
    rig = replace(rig, cameras=(rig.cameras[0], replace(rig.cameras[1], skew_ppm=40.0)),
                  triggers=TriggerTrain(hz=5, duty=0.3, jitter_ns=2_000, miss_rate=0.1, channel=3))
    bag = tmp_path_factory.mktemp('verify') / 'bag'
    return bag, write_rig(rig, simulate(rig), bag)


def _verify(capsys, *args):
    capsys.readouterr()
    code = cli.main(['verify', *map(str, args), '--json'])
    return code, json.loads(capsys.readouterr().out)


def test_the_error_reported_is_the_estimate_s_error_against_the_truth(two_makes, capsys, tmp_path):
    bag, truth = two_makes
    code, out = _verify(capsys, bag, '--reference', '/make_a/events', '--plot', tmp_path / 'v.png')
    assert code == 0
    cam = next(c for c in out['estimate']['cameras'] if c['topic'] == '/make_b/events')
    b = next(v for v in out['verified'] if v['topic'] == '/make_b/events')
    t = next(c for c in truth['cameras'] if c['topic'] == '/make_b/events')
    true = ClockCorrection(offset_ns=t['offset_ns'], skew_ppm=t['skew_ppm'], anchor_ns=t['anchor_ns'])
    at = cam['anchor_ns']
    true_error = cam['offset_ns'] - (true.apply_one(at) - at)
    assert b['verdict'] == 'verified' and b['source'] == '/make_b/trigger' and b['channel'] == 3
    assert b['matched'] > 100 and b['period_ns'] == 200_000_000
    # the edges' jitter (2 us each, over a hundred) and evt3's microsecond: within 2 us of the truth
    assert abs(b['error_ns'] - true_error) < 2_000, (b['error_ns'], true_error)
    assert abs(b['trigger_skew_ppm'] - (-40)) < 0.5  # the truth's 40 ppm, on the reference's timeline
    assert b['within'] == (abs(b['error_ns']) <= 3 * b['uncertainty_ns'])
    assert b['windows']['mean_abs_ns'] <= b['windows']['max_abs_ns']
    assert (tmp_path / 'v.png').stat().st_size > 0


def test_the_table_says_each_camera_s_edges_and_error(two_makes, capsys):
    bag, _ = two_makes
    capsys.readouterr()
    assert cli.main(['verify', str(bag), '--reference', '/make_a/events']) == 0
    text = capsys.readouterr().out
    assert '/make_a/events' in text and 'reference: the ruler' in text
    lines = text.splitlines()
    table = lines[next(i for i, x in enumerate(lines) if x.startswith('topic') and 'matched' in x):]
    b = next(x for x in table if x.startswith('/make_b/events')).split()
    assert b[1:3] == ['138', '3'] and b[7] == 'yes'  # make B's edges (all decoded from /make_b/trigger), within


def test_a_channel_not_among_the_cameras_is_refused(two_makes, capsys):
    bag, _ = two_makes
    capsys.readouterr()
    assert cli.main(['verify', str(bag), '--trigger-channel', '/nope=3']) != 0
    assert 'not a camera of the estimate' in capsys.readouterr().err


def test_a_1_khz_loopback_is_ambiguous(real_data, tmp_path, capsys):
    """Two copies of the real evt3 recording, the second 262 ms ahead: their 4,157 channel-6 edges
    (a 1 kHz loopback) cannot pick one pulse, and verify says so instead of an offset."""
    bag = merged_copies(real_data, 'evt3_sqlite3', tmp_path / 'merged', shift_ns=262_345_600)
    code, out = _verify(capsys, bag)
    b = next(v for v in out['verified'] if v['topic'] == '/b/events')
    assert code != 0
    assert b['verdict'] == 'ambiguous' and b['reason'] == 'ambiguous: period 1 ms'
    assert b['channels'] == {'6': 4157} and b['error_ns'] is None


def test_latencies_saved_by_verify_are_taken_out_by_estimate(two_makes, capsys, tmp_path):
    """Calibrate on the rig with triggers, then estimate with the file: make B's offset moves by the
    latency verify measured (minus the mean of its windows' errors), and the result says so."""
    bag, _ = two_makes
    lat = tmp_path / 'lat.json'
    code, out = _verify(capsys, bag, '--reference', '/make_a/events', '--save-latencies', lat)
    assert code == 0
    b = next(v for v in out['verified'] if v['topic'] == '/make_b/events')
    doc = json.loads(lat.read_text())
    assert doc['format'] == 'evsync-latencies/1' and doc['reference'] == '/make_a/events'
    assert doc['latencies_ns'] == {'/make_a/events': 0, '/make_b/events': -round(b['windows']['mean_ns'])}
    assert doc['measured']['cameras']['/make_b/events']['events_per_s'] > 0
    _, plain = _estimate(capsys, bag, '--reference', '/make_a/events')
    _, calibrated = _estimate(capsys, bag, '--reference', '/make_a/events', '--latencies', lat)
    moved = calibrated['cameras'][1]['offset_ns'] - plain['cameras'][1]['offset_ns']
    assert moved == doc['latencies_ns']['/make_b/events']
    assert calibrated['latencies_ns'] == doc['latencies_ns'] and calibrated['latencies_file'] == str(lat.resolve())
    assert 'latencies_ns' not in plain  # the contract unchanged where none are applied
    # under the other camera as reference, the same file: make A's offset moves the other way
    _, flipped = _estimate(capsys, bag, '--reference', '/make_b/events', '--latencies', lat)
    _, flipped_plain = _estimate(capsys, bag, '--reference', '/make_b/events')
    assert flipped['cameras'][1]['offset_ns'] - flipped_plain['cameras'][1]['offset_ns'] == -moved


def test_a_camera_given_a_latency_twice_is_refused(two_makes, capsys, tmp_path):
    bag, _ = two_makes
    lat = tmp_path / 'lat.json'
    assert cli.main(['verify', str(bag), '--reference', '/make_a/events', '--save-latencies', str(lat)]) == 0
    capsys.readouterr()
    assert cli.main(['estimate', str(bag), '--latencies', str(lat), '--latency-us', '/make_b/events=5']) == 2
    assert 'a latency in' in capsys.readouterr().err
    (tmp_path / 'other.json').write_text('{"reference": "/a"}')
    assert cli.main(['estimate', str(bag), '--latencies', str(tmp_path / 'other.json')]) == 2
    assert 'not a latencies file' in capsys.readouterr().err


def test_the_node_takes_the_latencies_file(two_makes, capsys, tmp_path):
    from evsync_ros.errors import ParameterError
    from evsync_ros.ros.parameters import node_config, node_defaults
    bag, _ = two_makes
    lat = tmp_path / 'lat.json'
    assert cli.main(['verify', str(bag), '--reference', '/make_a/events', '--save-latencies', str(lat)]) == 0
    doc = json.loads(lat.read_text())
    values = {**node_defaults(), 'topics': ['/make_a/events', '/make_b/events'],
              'types': ['event_camera_msgs/msg/EventPacket', 'dvs_msgs/msg/EventArray'], 'latencies_file': str(lat)}
    assert node_config(values).latencies_ns == doc['latencies_ns']
    with pytest.raises(ParameterError, match='envelope_latency_us'):
        node_config({**values, 'envelope_latency_us': [0.0, 3.0]})


def _estimate(capsys, bag, *args):
    capsys.readouterr()
    code = cli.main(['estimate', str(bag), *map(str, args), '--json'])
    return code, json.loads(capsys.readouterr().out)


def test_estimate_on_the_edges_takes_the_camera_s_line_from_them(two_makes, capsys):
    """estimate --trigger-channel: the rule the node decides by (``triggers.by_edges``), offline; its
    offset within 2 us of the truth, the density's own kept beside it."""
    bag, truth = two_makes
    channels = ['--trigger-channel', '/make_a/events=3', '/make_b/events=3']
    code, doc = _estimate(capsys, bag, '--reference', '/make_a/events', *channels)
    assert code == 0
    b = doc['cameras'][1]
    t = next(c for c in truth['cameras'] if c['topic'] == '/make_b/events')
    true = ClockCorrection(offset_ns=t['offset_ns'], skew_ppm=t['skew_ppm'], anchor_ns=t['anchor_ns'])
    at = b['anchor_ns']
    assert abs(b['offset_ns'] - (true.apply_one(at) - at)) < 2_000
    assert b['trigger_edges'] > 100 and b['density_offset_ns'] != b['offset_ns']
    capsys.readouterr()
    assert cli.main(['estimate', str(bag), '--trigger-channel', '/make_b/events=3']) == 2
    assert "or two cameras' channels" in capsys.readouterr().err


def test_estimate_ties_two_cameras_edge_to_edge_when_the_reference_gives_none(tmp_path, capsys):
    """Three cameras, the reference's channel not given: the two with edges are tied to each other
    (``triggers.tie``), the better known keeping its density line; their mutual offset within 2 us of
    the truth's, their density decisions' tens of microseconds off it."""
    rig = preset('mixed-models', seed=3, duration_s=16, triggers_hz=5)
    rig = replace(rig, cameras=(rig.cameras[0], replace(rig.cameras[1], encoding='evt3'), rig.cameras[2]))
    truth = write_rig(rig, simulate(rig), tmp_path / 'bag')
    p, x = '/prophesee/events', '/dvxplorer/events'
    base = [tmp_path / 'bag', '--reference', '/davis/events']
    _, alone = _estimate(capsys, *base)
    code, tied = _estimate(capsys, *base, '--trigger-channel', f'{p}=0', f'{x}=0')
    assert code == 0

    def apart(doc):
        err, first = {}, next(c for c in doc['cameras'] if c['topic'] == p)
        instant = first['anchor_ns'] + first['offset_ns']  # on the reference's timeline
        for topic in (p, x):
            c = next(c for c in doc['cameras'] if c['topic'] == topic)
            t = next(c for c in truth['cameras'] if c['topic'] == topic)
            true = ClockCorrection(offset_ns=t['offset_ns'], skew_ppm=t['skew_ppm'], anchor_ns=t['anchor_ns'])
            mine = ClockCorrection(offset_ns=c['offset_ns'], skew_ppm=c['skew_ppm'], anchor_ns=c['anchor_ns'])
            at = instant - t['offset_ns']  # the camera's time of it
            err[topic] = mine.apply_one(at) - true.apply_one(at)
        return err[p] - err[x]
    cams = {c['topic']: c for c in tied['cameras']}
    held, moved = sorted((p, x), key=lambda t: 'trigger_tied_to' in cams[t])
    assert cams[moved]['trigger_tied_to'] == held and 'trigger_edges' not in cams[held]
    assert cams[moved]['uncertainty_ns'] >= cams[held]['uncertainty_ns']
    assert abs(apart(tied)) < 2_000, apart(tied)
    assert abs(apart(alone)) > 30_000, apart(alone)
