"""evsync report and the bag commands through the command line, on simulated and real bags."""

import json

import pytest

from evsync_ros.cli import main as cli
from evsync_ros.cli.plots import d_curve
from evsync_ros.sim.pixelsim import preset, simulate
from evsync_ros.sim.simbag import write_rig


@pytest.fixture(scope='module')
def drift_bag(tmp_path_factory):
    d = tmp_path_factory.mktemp('drift')
    rig = preset('drift', seed=4, duration_s=45)
    truth = write_rig(rig, simulate(rig), d / 'bag', storage='mcap')
    return d / 'bag', rig, truth


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_report_from_a_bag_prints_history_and_plots(tmp_path, capsys, drift_bag):
    bag, rig, truth = drift_bag
    code, out, _ = run(capsys, 'report', bag, '--reference', rig.reference, '--plot', tmp_path / 'r.png')
    assert code == 0
    assert '2 pass(es)' in out  # the drifting cameras were binned again with their skew taken out
    for cam in truth['cameras']:
        assert cam['topic'] in out
    states = ('agrees', 'disagrees', 'no clear peak', 'no data (too little covered)')
    window_lines = [line for line in out.splitlines() if line.rstrip().endswith(states)]
    assert len(window_lines) >= 2 * 5  # a line per window per camera, each saying how it stands
    assert sum(line.endswith(' agrees') for line in window_lines) >= 2 * 3
    assert (tmp_path / 'r.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_estimate_json_restamp_and_report_from_json(tmp_path, capsys, drift_bag):
    bag, rig, truth = drift_bag
    code, out, _ = run(capsys, 'estimate', bag, '--reference', rig.reference, '--json')
    assert code == 0
    (tmp_path / 'est.json').write_text(out)
    est = json.loads(out)
    true_skew = {c['topic']: c['skew_ppm'] for c in truth['cameras']}
    for cam in est['cameras']:
        assert cam['skew_ppm'] == pytest.approx(true_skew[cam['topic']], abs=2.0)
    code, out, _ = run(capsys, 'restamp', bag, tmp_path / 'out', '--offsets', tmp_path / 'est.json')
    assert code == 0 and 'wrote' in out
    code, out, _ = run(capsys, 'estimate', tmp_path / 'out', '--reference', rig.reference, '--json')
    again = {c['topic']: c for c in json.loads(out)['cameras']}
    dvs = [c['topic'] for c in truth['cameras'] if c['encoding'] == 'dvs']
    assert dvs and all(abs(again[t]['offset_ns']) < 100_000 and abs(again[t]['skew_ppm']) < 2 for t in dvs)
    code, out, _ = run(capsys, 'report', tmp_path / 'est.json', '--plot', tmp_path / 'j.png')
    assert code == 0 and rig.reference in out and (tmp_path / 'j.png').stat().st_size > 1000
    code, _, err = run(capsys, 'restamp', bag, tmp_path / 'out', '--offsets', tmp_path / 'est.json')
    assert code == 2 and 'refusing to overwrite' in err


def test_paper_method_on_a_bag_and_a_clear_error_for_a_wrong_topic(tmp_path, capsys, drift_bag):
    bag, rig, _ = drift_bag
    code, out, _ = run(capsys, 'estimate', bag, '--method', 'paper', '--reference', rig.reference)
    assert code in (0, 1) and rig.reference in out
    code, _, err = run(capsys, 'restamp', bag, tmp_path / 'o', '--topics', '/nope')
    assert code == 2 and '/nope' in err and not (tmp_path / 'o').exists()


def test_d_curve_has_its_minimum_at_the_estimate(drift_bag):
    from evsync_ros.bag.estimate import estimate_bag
    bag, rig, _ = drift_bag
    est = estimate_bag(bag, reference=rig.reference)
    cam = est.rig.cameras[1]
    best = next(w for w in est.windows[cam.topic] if w.ref_counts.size)
    centre = best.ref_start_ns + 5 * 10**9 - best.offset_ns
    ms, d = d_curve(best, cam.correction.apply_one(centre) - centre, tau_ns=10**6)
    assert ms.size == 101 and abs(ms[d.argmin()]) <= 1.0


def test_real_recordings_estimate_and_report(tmp_path, capsys, real_data):
    for name in ('evt3_sqlite3', 'libcaer_cmp_mcap'):
        code, out, _ = run(capsys, 'report', real_data / name)
        assert code == 0 and '/event_camera/events' in out


def test_a_drifting_evt3_camera_restamps_onto_the_reference(tmp_path, capsys, drift_bag):
    bag, rig, truth = drift_bag
    code, _, _ = run(capsys, 'restamp', bag, tmp_path / 'out', '--reference', rig.reference)
    assert code == 0
    code, out, _ = run(capsys, 'estimate', tmp_path / 'out', '--reference', rig.reference, '--json')
    evt3 = [c['topic'] for c in truth['cameras'] if c['encoding'] == 'evt3' and c['topic'] != rig.reference]
    again = {c['topic']: c for c in json.loads(out)['cameras']}
    assert all(abs(again[t]['skew_ppm']) < 2 and abs(again[t]['offset_ns']) < 100_000 for t in evt3)
