"""bench/node.py's consumer view measures what an evt3 consumer of the node's outputs decodes: fed the
benchmark's own messages, unrestamped, it must see the cameras as far apart as their stamps put them;
restamped by the right correction, on one timeline, from the packet the correction reached them on
(a live restamper: the consumer anchored once, before)."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import pytest

from evsync_ros.core.clock import ClockCorrection
from msg_adapters.registry import Restamper

RATE, SECONDS, CAMERAS, MESSAGE_NS = 300_000.0, 2.0, 3, 1_000_000
PACKET = 'event_camera_msgs/msg/EventPacket'


@pytest.fixture(scope='module')
def bench() -> ModuleType:
    spec = importlib.util.spec_from_file_location('bench_node', Path(__file__).parents[2] / 'bench' / 'node.py')
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_unrestamped_inputs_are_as_far_apart_as_their_stamps(bench: ModuleType) -> None:
    messages = bench.build_messages('evt3', RATE, SECONDS, CAMERAS, MESSAGE_NS)
    kept = [(cam, k, bytes(raw)) for k, (_, cam, raw) in enumerate(messages)]
    view = bench.consumer_view(kept, RATE, SECONDS, CAMERAS, MESSAGE_NS)
    errors = bench.consumer_errors(view, {1: 0, 2: 0}, settle_ns=0)
    apart = bench.stamp_latency_ns(2) - bench.stamp_latency_ns(0)
    assert errors['consumer_ref_spread_us'] <= 1.0
    assert errors['consumer_after_max_us'] == pytest.approx(apart / 1e3, abs=1.0)
    assert errors['consumer_after_packets'] == sum(1 for _, cam, _ in messages if cam)


def test_restamped_from_mid_stream_the_consumer_sees_one_timeline_from_then_on(bench: ModuleType) -> None:
    messages = bench.build_messages('evt3', RATE, SECONDS, CAMERAS, MESSAGE_NS)
    restampers = [Restamper(PACKET, live=True) for _ in range(CAMERAS)]
    switch = len(messages) // 2  # before it: no correction (the consumers anchor there); after: the right one
    kept = []
    for k, (_, cam, raw) in enumerate(messages):
        offset = bench.stamp_latency_ns(0) - bench.stamp_latency_ns(cam) if k >= switch else 0
        kept.append((cam, k, bytes(restampers[cam].restamp(bytes(raw), ClockCorrection(offset_ns=offset)))))
    view = bench.consumer_view(kept, RATE, SECONDS, CAMERAS, MESSAGE_NS)
    errors = bench.consumer_errors(view, {1: switch, 2: switch}, settle_ns=0)
    assert errors['consumer_after_max_us'] <= 2.0  # evt3 carries microseconds
    assert errors['consumer_before_max_us'] == pytest.approx(3400.0, abs=2.0)
