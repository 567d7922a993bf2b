"""evsync_node as a ROS user's habits expect it (issue 52): ``--help`` says how and exits, a
misspelt or retired parameter is named in the log, and rclpy's ``qos_overrides`` parameters win
over the node's own QoS parameters for the topics they name, in its own process or its camera
processes'. Over real DDS on loopback, the node its own process."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip('rclpy', reason='rclpy is installed by ./dev setup')

from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from evsync_ros.ros.parameters import NODE_PARAMETERS
from evsync_testing.listen import Spinning

BIN = Path(sys.executable).parent
EVT3 = 'event_camera_msgs/msg/EventPacket'


def test_help_says_how_to_start_it_and_every_parameter_and_starts_nothing():
    for flag in ('--help', '-h'):
        done = subprocess.run([str(BIN / 'evsync_node'), flag], capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
        out = done.stdout
        assert out.startswith('usage: evsync_node') and 'docs/node.md' in out and 'config/evsync.yaml' in out
        assert 'qos_overrides.<topic>.<publisher|subscription>' in out
        for name in NODE_PARAMETERS:
            assert f'\n  {name} ' in out or f'\n  {name}  ' in out, name
        assert 'synchronising' not in out + done.stderr and not done.stderr  # the node never started


def _start(tmp_path: Path, params: dict, *ros_args: str) -> subprocess.Popen[str]:
    path = tmp_path / 'params.yaml'
    path.write_text(json.dumps({'evsync': {'ros__parameters': params},
                                'other_node': {'ros__parameters': {'frobnicate': 1}}}))  # not evsync's business
    return subprocess.Popen([str(BIN / 'evsync_node'), '--ros-args', '--params-file', str(path), *ros_args],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _qos(listener: Spinning, topic: str, kind: str, *, timeout_s: float = 30.0):
    """The QoS the node's endpoint on ``topic`` offers (``publisher``) or asks (``subscription``)."""
    find = listener.node.get_publishers_info_by_topic if kind == 'publisher' else \
        listener.node.get_subscriptions_info_by_topic
    deadline = time.monotonic() + timeout_s
    while True:
        infos = [i for i in find(topic) if i.node_name.startswith('evsync')]
        if infos:
            return infos[0].qos_profile
        assert time.monotonic() < deadline, f'no {kind} of the node on {topic}'
        time.sleep(0.1)


@pytest.mark.parametrize('processes', ['one', 'per_camera'])
def test_qos_overrides_win_and_unknown_parameters_are_named(tmp_path, processes):
    params = {'topics': ['/ha', '/hb'], 'types': [EVT3], 'qos': 'sensor_data', 'output_reliability': 'reliable',
              'processes': processes, 'hop_s': 5.0,
              'qos_overrides': {'/ha/synced': {'publisher': {'reliability': 'best_effort'}},
                                '/hb': {'subscription': {'reliability': 'reliable'}}}}
    node = _start(tmp_path, params, '-p', 'windw_s:=5.0', '-p', 'use_sim_time:=false', '-p',
                  'qos_overrides./hc.subscription.depth:=7')
    listener = Spinning('habits_listener')
    try:
        # what the parameters say, unless an override names the topic
        assert _qos(listener, '/ha/synced', 'publisher').reliability == ReliabilityPolicy.BEST_EFFORT
        assert _qos(listener, '/hb/synced', 'publisher').reliability == ReliabilityPolicy.RELIABLE
        assert _qos(listener, '/ha', 'subscription').reliability == ReliabilityPolicy.BEST_EFFORT
        assert _qos(listener, '/hb', 'subscription').reliability == ReliabilityPolicy.RELIABLE
        assert _qos(listener, '/hb/synced', 'publisher').durability == DurabilityPolicy.VOLATILE
    finally:
        listener.close()
        node.terminate()
        log = node.communicate(timeout=30)[0]
    assert node.returncode == 0, log
    warned = [line for line in log.splitlines() if '[WARN]' in line and 'parameter' in line]
    assert len([w for w in warned if 'windw_s (did you mean window_s?) is not a parameter of evsync_node' in w]) == 1
    assert len([w for w in warned if 'hop_s' in w and 'deprecated' in w]) == 1, log  # once, camera processes or not
    assert len([w for w in warned if 'qos_overrides./hc.subscription.depth' in w]) == 1, log  # no such topic
    assert len(warned) == 3, warned  # use_sim_time, the overrides used and the other node's entry: not unknown


@pytest.mark.parametrize('reliability', [None, 'reliable'])
def test_the_outputs_reliability_is_said_at_start(tmp_path, reliability):
    """Best effort by default (docs/node.md says why): said at start, with what a reliable subscriber
    needs."""
    params = {'topics': ['/ra', '/rb'], 'types': [EVT3]}
    if reliability:
        params['output_reliability'] = reliability
    node = _start(tmp_path, params)
    said: list[str] = []
    try:
        assert node.stdout is not None
        while not any('synchronising' in line for line in said):
            line = node.stdout.readline()
            assert line, said
            said.append(line)
    finally:
        node.terminate()
        said.append(node.communicate(timeout=30)[0])
    start = next(line for line in said if 'synchronising' in line)
    if reliability:
        assert '(reliable, depth 1000)' in start and 'best effort' not in ''.join(said)
    else:
        assert '(best_effort, depth 1000)' in start
        assert any('[INFO]' in line and 'outputs offered best effort' in line and 'output_reliability: reliable'
                   in line for line in said), said
