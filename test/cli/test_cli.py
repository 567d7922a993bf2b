"""The command line: the README's main job (demo), simulate and estimate."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

from evsync_ros.cli.main import main


def test_demo_json_recovers_known_offsets(capsys, tmp_path):
    assert main(['demo', '--json', '--duration', '12', '--plot', str(tmp_path / 'demo.png')]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['preset'] == 'mixed-models' and out['reference'] == '/prophesee/events'
    assert len(out['cameras']) == 3
    for cam in out['cameras']:
        assert cam['refined']['accepted']
        assert abs(cam['refined']['error_ns']) < 1_000_000  # sub-millisecond on this rig
        assert abs(cam['after_restamp_ns']) < 100_000  # the restamped bag is on the reference timeline
    assert out['plot'] == str(tmp_path / 'demo.png') and (tmp_path / 'demo.png').stat().st_size > 10_000


def test_demo_table_through_the_console_script(tmp_path):
    exe = shutil.which('evsync') or str(Path(sys.executable).with_name('evsync'))
    proc = subprocess.run([exe, 'demo', '--duration', '10', '--preset', 'same-model', '--keep', str(tmp_path)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert 'true offset s' in proc.stdout and '/cam1/events' in proc.stdout
    assert (tmp_path / 'same-model-seed0' / 'metadata.yaml').is_file()
    assert (tmp_path / 'same-model-seed0.truth.json').is_file()
    assert (tmp_path / 'same-model-seed0-restamped' / 'metadata.yaml').is_file()
    assert (tmp_path / 'evsync-demo.png').is_file() and 'after restamp' in proc.stdout


def test_simulate_then_estimate_json_contract(tmp_path, capsys):
    bag = tmp_path / 'rig'
    assert main(['simulate', str(bag), '--preset', 'same-model', '--duration', '12', '--storage', 'mcap']) == 0
    assert main(['simulate', str(bag), '--preset', 'same-model', '--duration', '12']) == 2  # refuses to overwrite
    truth = json.loads((tmp_path / 'rig.truth.json').read_text())
    capsys.readouterr()
    assert main(['estimate', str(bag), '--json', '--reference', truth['reference']]) == 0
    out = capsys.readouterr().out
    result = json.loads(out)  # exactly one JSON object on stdout
    assert out.count('\n') == 1
    assert result['reference'] == truth['reference']
    assert [c['topic'] for c in result['cameras']] == [truth['reference']] + sorted(
        c['topic'] for c in truth['cameras'] if c['topic'] != truth['reference'])
    first = ['topic', 'offset_ns', 'skew_ppm', 'anchor_ns', 'accepted', 'cost', 'confidence', 'window_ns']
    added = ['uncertainty_ns', 'skew_uncertainty_ppm', 'reason', 'windows_agreeing', 'windows_total',
             'spread_ns', 'prior', 'prior_reason']
    assert all(list(c) == first + added for c in result['cameras'])  # fields added after the first, none changed
    assert all(c['accepted'] and c['reason'] == '' and c['uncertainty_ns'] < 500_000 for c in result['cameras'])
    assert result['cameras'][0]['offset_ns'] == 0
    by_topic = {c['topic']: c for c in truth['cameras']}
    from evsync_ros.sim.simbag import error_ns
    for cam in result['cameras'][1:]:
        assert abs(error_ns(cam, by_topic[cam['topic']], by_topic[cam['topic']]['anchor_ns'] + 6 * 10**9)) < 500_000


def test_estimate_names_bad_inputs(tmp_path, capsys):
    assert main(['estimate', str(tmp_path / 'nothing')]) == 2
    assert 'no such bag' in capsys.readouterr().err


def test_bad_parameters_give_a_clear_error_and_exit_2(capsys):
    assert main(['demo', '--epsilon', 'nan']) == 2
    assert 'epsilon' in capsys.readouterr().err
