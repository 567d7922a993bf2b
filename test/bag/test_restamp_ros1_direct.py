"""A ROS 1 bag restamped into a ROS 1 bag: event messages restamped as their ROS 1 bytes
(``Restamper.restamp_ros1``: plain evt3 packets, dvs EventArrays; no conversion to CDR and back) give
the output that converting each one gives, byte for byte and in the same order, under an offset, a
skew (that rewrites evt3 time words) and an offset past evt3's re-anchoring limit; and so does
restamping it a chunk at a time (``restamp._copy_chunks``)."""

from __future__ import annotations

import pytest

from evsync_ros.bag import restamp
from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.core.clock import ClockCorrection
from evsync_testing.digest import bag_digest
from msg_adapters.registry import Restamper

EVT3 = '/event_camera/events'
RECORDINGS = {'evt3_sqlite3': (EVT3, EVT3), 'dvs128_stereo/fan': ('/right/events', '/left/events')}
"""recording: (reference, the topic corrected)"""
CORRECTIONS = [ClockCorrection(offset_ns=12_345_678),
               ClockCorrection(offset_ns=-2_000_000, skew_ppm=80.0, anchor_ns=1_700_000_000_000_000_000),
               ClockCorrection(offset_ns=3_000_000_000)]


@pytest.fixture(scope='module', params=list(RECORDINGS))
def ros1_input(request, real_data, tmp_path_factory):
    """A real recording as a ROS 1 bag, its reference and the topic to correct."""
    reference, topic = RECORDINGS[request.param]
    bag = tmp_path_factory.mktemp('ros1') / 'input.bag'
    restamp_bag(real_data / request.param, bag, corrections={}, reference=reference)
    return bag, reference, topic


@pytest.mark.parametrize('corr', CORRECTIONS, ids=lambda c: f'{c.offset_ns}/{c.skew_ppm}')
def test_ros1_bytes_restamped_as_converted(ros1_input, tmp_path, monkeypatch, corr):
    """Three ways, one output: a chunk at a time (the default), message by message through
    ``restamp_ros1``, and message by message converted to CDR and back."""
    bag, reference, topic = ros1_input
    rep = restamp_bag(bag, tmp_path / 'chunks.bag', corrections={topic: corr}, reference=reference)
    monkeypatch.setattr(restamp, '_chunked', lambda *a, **k: None)
    calls = []
    direct = Restamper.restamp_ros1

    def counted(self, raw, correction):
        out = direct(self, raw, correction)
        calls.append(out is not None)
        return out

    monkeypatch.setattr(Restamper, 'restamp_ros1', counted)
    by_message = restamp_bag(bag, tmp_path / 'direct.bag', corrections={topic: corr}, reference=reference)
    restamped = sum(t.restamped for t in by_message.topics.values())
    assert rep.bad == 0 and all(calls) and len(calls) == restamped > 0
    assert rep.topics == by_message.topics
    monkeypatch.setattr(Restamper, 'restamp_ros1', lambda self, raw, correction: None)
    restamp_bag(bag, tmp_path / 'converted.bag', corrections={topic: corr}, reference=reference)
    assert bag_digest(tmp_path / 'direct.bag') == bag_digest(tmp_path / 'converted.bag')
    assert bag_digest(tmp_path / 'chunks.bag') == bag_digest(tmp_path / 'converted.bag')
