"""Parameter files: the shipped YAML holds the paper's defaults; bad files are refused by name."""

from pathlib import Path

import pytest

from evsync_ros import config
from evsync_ros.cli import main
from evsync_ros.errors import ParameterError
from evsync_ros.paper import PaperParams

SHIPPED = Path(__file__).resolve().parents[1] / 'config' / 'evsync.yaml'


def test_shipped_yaml_holds_the_paper_defaults():
    values = config.load_ros_parameters(SHIPPED)
    assert config.paper_params_from(values, source=str(SHIPPED)) == PaperParams()


def test_values_are_converted_and_checked(tmp_path):
    f = tmp_path / 'p.yaml'
    f.write_text('/**:\n  ros__parameters:\n    tau_ms: 0.5\n    window_s: 4\n')
    params = config.paper_params_from(config.load_ros_parameters(f), source=str(f))
    assert (params.tau_ns, params.window_ns) == (500_000, 4_000_000_000)
    with pytest.raises(ParameterError, match='epsilon must be a number'):
        config.paper_params_from({'epsilon': 'small'}, source='x')
    with pytest.raises(ParameterError, match='tau_ns'):
        config.paper_params_from({'tau_ms': -1.0}, source='x')


def test_unreadable_or_sectionless_files_are_named(tmp_path):
    with pytest.raises(ParameterError, match='nope.yaml'):
        config.load_ros_parameters(tmp_path / 'nope.yaml')
    f = tmp_path / 'other.yaml'
    f.write_text('other_node:\n  ros__parameters: {}\n')
    with pytest.raises(ParameterError, match='no evsync: ros__parameters'):
        config.load_ros_parameters(f)


def test_demo_reads_the_parameter_file_and_flags_override_it(tmp_path, capsys):
    f = tmp_path / 'p.yaml'
    f.write_text('evsync:\n  ros__parameters:\n    window_s: 8.0\n    epsilon: 0.01\n')
    assert main(['demo', '--duration', '10', '--params-file', str(f), '--epsilon', '0.001', '--plot', '']) == 0
    out = capsys.readouterr().out
    assert 'T 8 s' in out and 'epsilon 0.001' in out
