"""A bag's recorded /evsync/offsets as the corrections of a restamp (issue 24): the stream is read as
each camera's track; a bag without it, or with it of another type, is refused by name. (The round
trip against the truth, through a live node, is test/ros/test_node.py's.)"""

from __future__ import annotations

import json

import pytest

from evsync_ros.bag.restamp import load_offsets_stream
from evsync_ros.bag.writer import BagWriter
from evsync_ros.cli.main import main
from evsync_ros.errors import BagError


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    bag = tmp_path_factory.mktemp('offsets') / 'rig'
    assert main(['simulate', str(bag), '--preset', 'same-model', '--duration', '6']) == 0
    return bag, json.loads((bag.parent / 'rig.truth.json').read_text())


def test_a_bag_without_the_offsets_topic_is_refused_by_name(rig, tmp_path, capsys):
    bag, _ = rig
    with pytest.raises(BagError, match='no /evsync/offsets topic'):
        load_offsets_stream(bag)
    assert main(['restamp', str(bag), str(tmp_path / 'out'), '--offsets', str(bag)]) == 2
    assert 'no /evsync/offsets topic' in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()


def test_an_offsets_topic_of_another_type_or_empty_is_refused(tmp_path):
    wrong = tmp_path / 'wrong'
    with BagWriter(wrong) as w:
        w.add_topic('/evsync/offsets', 'std_msgs/msg/String')
    with pytest.raises(BagError, match='not sensor_msgs/msg/TimeReference'):
        load_offsets_stream(wrong)
    empty = tmp_path / 'empty'
    with BagWriter(empty) as w:
        w.add_topic('/evsync/offsets', 'sensor_msgs/msg/TimeReference')
    with pytest.raises(BagError, match='holds no offsets'):
        load_offsets_stream(empty)
