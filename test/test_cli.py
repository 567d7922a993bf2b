"""The README's main job: the demo estimates the simulated rig's known offsets."""

import json
import shutil
import subprocess
import sys


from evsync_ros.cli import main


def test_demo_json_recovers_known_offsets(capsys):
    assert main(['demo', '--json']) == 0
    out = json.loads(capsys.readouterr().out)
    assert out['method'] == 'paper' and out['reference'] == '/prophesee/events'
    assert len(out['cameras']) == 3
    for cam in out['cameras']:
        assert cam['accepted']
        assert abs(cam['offset_ns'] - cam['true_offset_ns']) < 1_500_000  # 1.5 bins of 1 ms


def test_demo_table_through_the_console_script():
    exe = shutil.which('evsync') or str(__import__('pathlib').Path(sys.executable).with_name('evsync'))
    proc = subprocess.run([exe, 'demo', '--duration', '12'], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert 'true offset s' in proc.stdout and '/davis/events' in proc.stdout


def test_bad_parameters_give_a_clear_error_and_exit_2(capsys):
    assert main(['demo', '--epsilon', 'nan']) == 2
    assert 'epsilon' in capsys.readouterr().err
