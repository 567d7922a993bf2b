"""Parameter files: the shipped YAML holds the paper's defaults; bad files are refused by name."""

from pathlib import Path

import pytest

from evsync_ros.cli.main import main
from evsync_ros.core.paper import PaperParams
from evsync_ros.errors import ParameterError
from evsync_ros.ros import parameters as config
from evsync_ros.ros.modes import BeforeLock, Estimator, Executor, Processes, Qos, Reliability, Republish

SHIPPED = Path(__file__).resolve().parents[2] / 'config' / 'evsync.yaml'


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


def test_shipped_yaml_holds_every_node_parameter_and_they_check_out():
    values = config.node_defaults(SHIPPED)
    assert set(values) == set(config.NODE_PARAMETERS)
    cfg = config.node_config(values)
    assert cfg.reference == cfg.topics[0] and cfg.outputs == tuple(t + '/synced' for t in cfg.topics)
    assert cfg.online.refined.max_shift_ns == 500_000_000 and cfg.online.paper == PaperParams()
    assert len(cfg.types) == len(cfg.topics)  # one type given serves every topic


@pytest.mark.parametrize(('change', 'match'), [
    ({'topics': ['/a']}, 'two to eight'),
    ({'topics': ['/a', 'b']}, 'absolute'),
    ({'types': ['std_msgs/msg/String']}, 'not an event message type'),
    ({'types': ['dvs_msgs/msg/EventArray'] * 3}, 'one per topic'),
    ({'reference': '/z'}, 'reference'),
    ({'window_s': 0.1}, r'window_s must be double in \[0.5, 120\]'),
    ({'window_s': float('nan')}, 'window_s'),
    ({'qos_depth': 2.5}, 'qos_depth must be integer'),
    ({'before_lock': 'drop'}, 'before_lock .*forward, hold, coarse'),
    ({'output_reliability': 'sometimes'}, 'output_reliability must be string .one of best_effort, reliable.'),
    ({'output_suffix': '', 'output_namespace': ''}, 'outputs would be the inputs'),
    ({'tau_ms': 0.03}, 'tau_ns'),
    ({'envelope_latency_us': [0.0, 400.0, 0.0]}, 'one latency per topic'),
    ({'envelope_latency_us': []}, 'envelope_latency_us must be double array'),
    ({'envelope_latency_us': [0.0, 2e6]}, r'envelope_latency_us must be double array in \[-1e\+06, 1e\+06\]'),
    ({'companions': ['/cam0/imu'], 'companion_types': ['sensor_msgs/msg/Imu']}, 'not TOPIC=EVENT_TOPIC'),
    ({'companions': ['/cam0/imu=/cam9/events'], 'companion_types': ['sensor_msgs/msg/Imu']}, 'not one of topics'),
    ({'companions': ['/cam1/events=/cam0/events'], 'companion_types': ['sensor_msgs/msg/Imu']}, 'already an event'),
    ({'companions': ['/a=/cam0/events', '/b=/cam1/events'], 'companion_types': ['x/msg/A'] * 3}, 'one per companion'),
    ({'companion_types': ['sensor_msgs/msg/Imu']}, 'without companions'),
    ({'companions': ['/x=/cam0/events'], 'companion_types': ['dvs_msgs/msg/EventArray']}, 'has an event type'),
])
def test_bad_node_parameters_are_named(change, match):
    values = {**config.node_defaults(SHIPPED), **change}
    with pytest.raises(ParameterError, match=match):
        config.node_config(values, source='test')


def test_envelope_latencies_are_one_per_topic_or_none():
    values = config.node_defaults(SHIPPED)
    assert config.node_config(values).latencies_ns == {}  # the default: one value for all, no correction
    values['envelope_latency_us'] = [0.0, 400.5]
    assert config.node_config(values).latencies_ns == {'/cam0/events': 0, '/cam1/events': 400_500}


def test_companions_are_optional_and_follow_the_outputs_naming():
    values = config.node_defaults(SHIPPED)
    assert values['companions'] is None and config.node_config(values).companions == ()
    values.update(companions=['/cam0/imu=/cam0/events', '/cam1/image=/cam1/events'],
                  companion_types=['sensor_msgs/msg/Imu', 'sensor_msgs/msg/Image'])
    cfg = config.node_config(values)
    assert [(c.topic, c.camera, c.msgtype, c.output) for c in cfg.companions] == [
        ('/cam0/imu', '/cam0/events', 'sensor_msgs/msg/Imu', '/cam0/imu/synced'),
        ('/cam1/image', '/cam1/events', 'sensor_msgs/msg/Image', '/cam1/image/synced')]
    values['output_namespace'] = '/rig'
    assert [c.output for c in config.node_config(values).companions] == ['/rig/cam0/imu', '/rig/cam1/image']


def test_output_namespace_replaces_the_suffix():
    values = {**config.node_defaults(SHIPPED), 'output_namespace': '/synced/'}
    assert config.node_config(values).outputs == ('/synced/cam0/events', '/synced/cam1/events')


def test_the_cli_reads_a_parameter_file_as_rcl_resolves_it_for_the_node(tmp_path):
    """issue 24: wildcards merged under the node's own keys, ``/**/evsync`` matched, another node's
    section left out, as evsync_node itself (rcl) would read the file."""
    f = tmp_path / 'rig.yaml'
    f.write_text('/**:\n  ros__parameters:\n    tau_ms: 2.0\n    window_s: 4.0\n'
                 '/**/evsync:\n  ros__parameters:\n    window_s: 5.0\n'
                 'evsync:\n  ros__parameters:\n    epsilon: 0.001\n'
                 'other:\n  ros__parameters:\n    epsilon: 9.0\n')
    assert config.load_ros_parameters(f, rcl=True) == {'tau_ms': 2.0, 'window_s': 5.0, 'epsilon': 0.001}
    assert config.load_ros_parameters(f) == {'epsilon': 0.001}  # without rcl: the node's own section only
    only = tmp_path / 'other.yaml'
    only.write_text('other_node:\n  ros__parameters:\n    tau_ms: 2.0\n')
    with pytest.raises(ParameterError, match='no parameters for node evsync'):
        config.load_ros_parameters(only, rcl=True)
    broken = tmp_path / 'broken.yaml'
    broken.write_text('evsync: [\n')
    with pytest.raises(ParameterError, match='broken.yaml'):
        config.load_ros_parameters(broken, rcl=True)


def test_modes_are_members_not_text():
    cfg = config.node_config(config.node_defaults(SHIPPED))
    assert (cfg.qos, cfg.before_lock, cfg.processes, cfg.republish, cfg.executor, cfg.estimator) == (
        Qos.SENSOR_DATA, BeforeLock.COARSE, Processes.ONE, Republish.ALL, Executor.EVENTS, Estimator.PROCESS)
    assert isinstance(cfg.output_reliability, Reliability)
    values = {**config.node_defaults(SHIPPED), 'before_lock': 'hold', 'processes': 'per_camera'}
    cfg = config.node_config(values)
    assert cfg.before_lock is BeforeLock.HOLD and cfg.processes is Processes.PER_CAMERA
    assert str(cfg.before_lock) == 'hold'  # as it was written


def test_unknown_parameters_are_named_with_the_nearest_known_one():
    entities = {'/cam0/events/synced.publisher', '/cam0/events.subscription'}
    unknown, deprecated = config.unknown_parameters(
        ['windw_s', 'window_s', 'use_sim_time', 'hop_s', 'frobnicate',
         'qos_overrides./cam0/events/synced.publisher.reliability', 'qos_overrides./cam0/events.subscription.depth',
         'qos_overrides./cam9/events.subscription.depth'], entities=entities)
    assert unknown == ['frobnicate', 'qos_overrides./cam9/events.subscription.depth (no publisher or subscription '
                       'of this node on that topic)', 'windw_s (did you mean window_s?)']
    assert deprecated == ["hop_s (not used since the paper's windows follow one another on every path)"]
    assert config.unknown_parameters(['qos_overrides./any.publisher.depth']) == ([], [])  # no entities: any topic


def test_hop_s_is_gone_from_the_shipped_file_and_log_summary_s_is_there():
    values = config.node_defaults(SHIPPED)
    assert 'hop_s' not in values and 'hop_s' not in config.NODE_PARAMETERS
    assert config.node_config(values).log_summary_ns == round(values['log_summary_s'] * 1e9)
    assert config.node_config({**values, 'log_summary_s': 0.0}).log_summary_ns == 0  # off
