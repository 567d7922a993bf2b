"""The definitions given to rosbags declare the same fields as the interface packages and the bags."""

import re
from pathlib import Path

import pytest

from evsync_ros.bag.reader import BagReader
from msg_adapters.definitions import EVENT_PACKET, MSG_DEFINITIONS

REPO = Path(__file__).resolve().parents[2]


def fields(text: str) -> list[str]:
    lines = (re.sub(r'#.*', '', line).strip() for line in text.splitlines())
    return [' '.join(line.split()) for line in lines if line]


@pytest.mark.parametrize('name', sorted(MSG_DEFINITIONS))
def test_embedded_definition_matches_the_interface_package(name):
    pkg, _, msg = name.split('/')
    msg_file = REPO / 'interfaces' / pkg / 'msg' / f'{msg}.msg'
    assert fields(MSG_DEFINITIONS[name]) == fields(msg_file.read_text())


def test_embedded_definition_matches_what_the_driver_recorded(real_data):
    with BagReader(real_data / 'evt3_sqlite3') as reader:
        (conn,) = reader.connections
    recorded = conn.msgdef.data.split('=' * 80)[0]  # the message itself, before its dependencies
    assert fields(recorded) == fields(MSG_DEFINITIONS[EVENT_PACKET])
