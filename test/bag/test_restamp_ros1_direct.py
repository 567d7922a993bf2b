"""A ROS 1 bag restamped into a ROS 1 bag: the plain evt3 packets restamped as ROS 1 bytes
(``Restamper.restamp_ros1``, no conversion to CDR and back) give the output that converting each one
gives, byte for byte and in the same order, under an offset, a skew that rewrites time words and an
offset past the re-anchoring limit."""

from __future__ import annotations

import hashlib

import pytest

from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.core.clock import ClockCorrection
from msg_adapters.registry import Restamper

EVT3 = '/event_camera/events'
CORRECTIONS = [ClockCorrection(offset_ns=12_345_678),
               ClockCorrection(offset_ns=-2_000_000, skew_ppm=80.0, anchor_ns=1_700_000_000_000_000_000),
               ClockCorrection(offset_ns=3_000_000_000)]


def digest(bag):
    """sha256 of a ROS 1 bag's topics and of its messages (topic, record time, own bytes) in read order."""
    h = hashlib.sha256()
    with BagReader(bag) as reader:
        for conn in sorted(reader.connections, key=lambda c: c.topic):
            h.update(repr((conn.topic, conn.msgtype, conn.msgdef.data, conn.digest, conn.ext)).encode())
        for conn, timestamp, raw in reader.messages(native=True):
            h.update(f'{conn.topic} {timestamp} {len(raw)}'.encode())
            h.update(raw)
    return h.hexdigest()


@pytest.fixture(scope='module')
def ros1_input(real_data, tmp_path_factory):
    """The real evt3 recording as a ROS 1 bag."""
    bag = tmp_path_factory.mktemp('ros1') / 'evt3.bag'
    restamp_bag(real_data / 'evt3_sqlite3', bag, corrections={}, reference=EVT3)
    return bag


@pytest.mark.parametrize('corr', CORRECTIONS, ids=lambda c: f'{c.offset_ns}/{c.skew_ppm}')
def test_ros1_bytes_restamped_as_converted(ros1_input, tmp_path, monkeypatch, corr):
    calls = []
    direct = Restamper.restamp_ros1

    def counted(self, raw, correction):
        out = direct(self, raw, correction)
        calls.append(out is not None)
        return out

    monkeypatch.setattr(Restamper, 'restamp_ros1', counted)
    rep = restamp_bag(ros1_input, tmp_path / 'direct.bag', corrections={EVT3: corr}, reference=EVT3)
    assert rep.bad == 0 and all(calls) and len(calls) == rep.topics[EVT3].restamped > 0
    monkeypatch.setattr(Restamper, 'restamp_ros1', lambda self, raw, correction: None)
    restamp_bag(ros1_input, tmp_path / 'converted.bag', corrections={EVT3: corr}, reference=EVT3)
    assert digest(tmp_path / 'direct.bag') == digest(tmp_path / 'converted.bag')
