"""The soak's input (``evsync_testing.evt3cycle``, sent by bench/soak.py) is what a camera would
send: one cycle of evt3 payloads sent again and again must decode as one stream whose sensor time runs
on, cycle after cycle, through the 24-bit wraps, with no step backwards and the same events 10.24 s
later."""

from __future__ import annotations

import numpy as np
import pytest

from evsync_testing import evt3cycle as soak
from msg_adapters.evt3 import Evt3Decoder

CYCLE_NS = soak.CYCLE_NS


def decoded(cycle: soak.Cycle, cycles: int) -> list[np.ndarray]:
    dec = Evt3Decoder(width=1280, height=720)
    return [dec.decode(cycle.payload(c, k)).t for c in range(cycles) for k in range(cycle.per_cycle)]


@pytest.mark.parametrize('message_ms', [10, 1])
def test_cycles_decode_as_one_stream_running_on_through_the_wraps(message_ms):
    cycle = soak.Cycle(20_000.0, seed=3, message_ns=message_ms * 1_000_000)  # 20 events per ms
    times = decoded(cycle, 4)  # 41 s: two 24-bit wraps (16.8 s)
    flat = np.concatenate(times)
    assert np.all(np.diff(flat) >= 0)
    n = cycle.per_cycle
    assert n == soak.CYCLE_NS // (message_ms * 1_000_000)
    for c in range(1, 4):
        for k in (0, 1, 511, n - 1):
            assert np.array_equal(times[c * n + k], times[k] + c * CYCLE_NS)
    assert flat[-1] - flat[0] > 3 * CYCLE_NS


@pytest.mark.parametrize('message_ms', [10, 1])
def test_bursts_come_every_sixth_cycle_with_ten_times_the_events(message_ms):
    cycle = soak.Cycle(20_000.0, seed=3, message_ns=message_ms * 1_000_000)
    k = cycle.burst_at + 10
    normal = cycle.events(0, k)
    burst = cycle.events(soak.BURST_EVERY - 1, k)
    assert 6 * normal < burst < 15 * normal if message_ms == 10 else burst > 3 * normal
    assert cycle.events(soak.BURST_EVERY, k) == normal
    times = decoded(cycle, soak.BURST_EVERY)
    assert np.all(np.diff(np.concatenate(times)) >= 0)  # the burst's payloads continue the stream
