"""The node's numeric status topics (ros/status.py): the numbers of one camera, and the PlotJuggler
layout of them (the shipped one and `evsync plotjuggler`). Over DDS: test_node.py."""

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from evsync_ros.cli.main import main as evsync
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine import State, Status
from evsync_ros.ros import parameters as config
from evsync_ros.ros import status

REPO = Path(__file__).resolve().parents[2]
SHIPPED_LAYOUT = REPO / 'config' / 'example_rig_plotjuggler.xml'


def _status(state: State, correction: ClockCorrection | None, **kw) -> Status:
    return Status(topic='/cam1/events', state=state, correction=correction, prior_ns=None, cost=0.0, confidence=0.75,
                  windows_tried=4, windows_accepted=3, jumps=0, events=10, far_events=0, silent_ns=None,
                  window_ns=None, message='', **kw)


def test_before_a_correction_the_offset_and_its_error_are_nan_and_the_state_a_code():
    v = status.camera_values(_status(State.WAITING, None), correction=None, last_time_ns=None, lost=0)
    assert set(v) == set(status.NAMES)
    assert math.isnan(v['offset_ms']) and math.isnan(v['skew_ppm']) and math.isnan(v['offset_std_ms'])
    assert v['state'] == 0.0 and v['confidence'] == 0.75 and v['messages_lost'] == 0.0
    assert [status.STATE_CODES[s] for s in State] == [0, 1, 2, 3, 4]  # one code each, as documented


def test_the_offset_is_the_one_in_force_at_the_newest_event_with_skew():
    c = ClockCorrection(offset_ns=2_500_000_000, skew_ppm=40.0, anchor_ns=1_000_000_000)
    s = _status(State.LOCKED, c, uncertainty_ns=12_000.0, skew_uncertainty_ppm=0.3)
    v = status.camera_values(s, correction=c, last_time_ns=11_000_000_000, lost=7)
    # 10 s after the anchor at 40 ppm: 0.4 ms more than the anchor's offset
    assert v['offset_ms'] == pytest.approx(2500.4, abs=1e-9)
    assert v['skew_ppm'] == 40.0 and v['offset_std_ms'] == pytest.approx(0.012)
    assert v['skew_std_ppm'] == pytest.approx(0.3) and v['state'] == 3.0 and v['messages_lost'] == 7.0
    # no event yet: the offset at the anchor
    assert status.camera_values(s, correction=c, last_time_ns=None, lost=0)['offset_ms'] == pytest.approx(2500.0)


def _curves(text: str) -> tuple[list[str], list[str]]:
    root = ET.fromstring(text)
    curves = [c.get('name', '') for c in root.iter('curve')]
    selected = root.find("./Plugins/plugin[@ID='ROS2 Topic Subscriber']/selected_topics")
    assert selected is not None
    return curves, selected.get('value', '').split(';')


def test_the_layout_plots_every_camera_s_offset_error_skew_and_state_from_its_topics():
    cams = ['/a/events', '/b/events', '/c/events']
    curves, selected = _curves(status.layout(cams, status_topic='/rig/status'))
    wanted = {f'/rig/status{cam}/{name}' for cam in cams for name, _ in status.PLOTS}
    assert set(selected) == wanted
    assert set(curves) == {t + '/data' for t in wanted}  # std_msgs/Float64: its one field, data
    assert {name for name, _ in status.PLOTS} <= set(status.NAMES)


def test_the_shipped_layout_is_the_example_rig_s_and_the_command_writes_it_without_overwriting(tmp_path, capsys):
    values = {**config.node_defaults(), **config.load_ros_parameters(REPO / 'config' / 'example_rig.yaml')}
    expected = status.layout(list(values['topics']), status_topic=values['status_topic'])
    regenerate = 'evsync plotjuggler --params-file config/example_rig.yaml -o config/example_rig_plotjuggler.xml'
    assert SHIPPED_LAYOUT.read_text() == expected, f'regenerate it: {regenerate}'
    out = tmp_path / 'layout.xml'
    assert evsync(['plotjuggler', '--params-file', str(REPO / 'config' / 'example_rig.yaml'), '-o', str(out)]) == 0
    assert out.read_text() == expected
    out.write_text('mine')
    assert evsync(['plotjuggler', '--topics', '/x/events', '/y/events', '-o', str(out)]) == 2
    assert out.read_text() == 'mine' and 'exists' in capsys.readouterr().err
    assert evsync(['plotjuggler', '--topics', '/x/events', '/y/events']) == 0
    curves, _ = _curves(capsys.readouterr().out)
    assert '/evsync/status/y/events/state/data' in curves
    assert evsync(['plotjuggler', '--topics', 'x/events', '/y/events']) == 2
    assert 'absolute' in capsys.readouterr().err
