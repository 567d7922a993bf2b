"""A camera process's counts: the wire form round-trips, bad batches are named, and an estimator fed
counts tracks exactly as one fed the event times."""

import numpy as np
import pytest

from evsync_ros.core.bins import BinnedStream
from evsync_ros.core.counts import MessageBins
from evsync_ros.core.engine import Engine
from evsync_ros.errors import StreamError
from evsync_ros.runtime.wire import pack, unpack
from evsync_testing.streams import BASE, bursty, thinned

MS = 1_000_000
S = 1_000_000_000

GRID = 100_000


def test_message_bins_count_every_event_in_its_grid_bin():
    rng = np.random.default_rng(1)
    times = rng.integers(5_000_000_000, 5_001_000_000, 1250).astype(np.int64)
    m = MessageBins.of(times, receipt_ns=7, grid_ns=GRID)
    expected_bins, expected_counts = np.unique(times // GRID, return_counts=True)
    assert np.array_equal(m.bins, expected_bins) and np.array_equal(m.counts, expected_counts)
    assert (m.lo_ns, m.hi_ns, m.mid_ns, m.events) == (int(times.min()), int(times.max()), int(times[625]), 1250)
    spread = np.array([0, 10 * S, 400 * S], np.int64)  # far apart: binned without a dense array between
    far = MessageBins.of(spread, receipt_ns=0, grid_ns=GRID)
    assert far.bins.tolist() == [0, 10 * S // GRID, 400 * S // GRID]


def test_the_wire_form_round_trips_and_names_a_bad_batch():
    times = np.arange(0, 3 * MS, 7_000, dtype=np.int64)
    batch = [MessageBins.of(times, receipt_ns=9 * MS, grid_ns=GRID),
             MessageBins.of(np.zeros(0, np.int64), receipt_ns=10 * MS, grid_ns=GRID),
             MessageBins.of(times + MS, receipt_ns=11 * MS, grid_ns=GRID, host_event_ns=5, host_ns=6)]
    camera, back = unpack(pack(batch, camera=3), source='/evsync/_counts')
    assert camera == 3 and len(back) == 3
    for a, b in zip(batch, back):
        assert (a.receipt_ns, a.mid_ns, a.lo_ns, a.hi_ns, a.host_event_ns, a.host_ns) == \
            (b.receipt_ns, b.mid_ns, b.lo_ns, b.hi_ns, b.host_event_ns, b.host_ns)
        assert np.array_equal(a.bins, b.bins) and np.array_equal(a.counts, b.counts)
    wire = pack(batch, camera=0)
    with pytest.raises(StreamError, match='/evsync/_counts: .*truncated'):
        unpack(wire[:-2 * batch[2].bins.size - 3], source='/evsync/_counts')
    with pytest.raises(StreamError, match='version'):
        unpack(np.r_[np.int64(9), wire[1:]], source='x')
    with pytest.raises(StreamError, match='after the last message'):
        unpack(np.r_[wire, np.int64(1)], source='x')
    reversed_bins = wire.copy()
    reversed_bins[3 + 7:3 + 7 + batch[0].bins.size] = reversed_bins[3 + 7:3 + 7 + batch[0].bins.size][::-1]
    with pytest.raises(StreamError, match='ascending'):
        unpack(reversed_bins, source='x')


def test_binned_stream_takes_bins_as_it_takes_times():
    rng = np.random.default_rng(2)
    by_times, by_bins = BinnedStream(grid_ns=GRID, origin_ns=0), BinnedStream(grid_ns=GRID, origin_ns=0)
    for k in range(50):
        times = np.sort(rng.integers(k * MS, (k + 1) * MS, 300)).astype(np.int64)
        if k == 20:
            times[5] = 200 * S  # a corrupt time, far from the rest
        by_times.add(times)
        m = MessageBins.of(times, receipt_ns=0, grid_ns=GRID)
        by_bins.add_bins(m.bins, m.counts, lo=m.lo_ns, hi=m.hi_ns, mid=m.mid_ns)
    assert np.array_equal(by_times.snapshot(0, 50 * MS).counts(0, GRID, 500),
                          by_bins.snapshot(0, 50 * MS).counts(0, GRID, 500))
    assert (by_bins.events, by_bins.far_events) == (by_times.events, by_times.far_events) == (15000, 1)


def feed(sync, *, by_bins, seconds=28):
    """Three cameras seeing one scene (offsets +2.3 s at 20 ppm and -40 ms against /a) in 20 ms
    messages arriving 1-4 ms after their last event, stepped every 500 ms; each message given to
    ``sync`` as its times, or (``by_bins``) as its counts."""
    truth = bursty(seconds + 2, seed=3, rate=60.0)
    rng = np.random.default_rng(103)
    clocks = {'/a': lambda t: t, '/b': lambda t: t - 2_345_678_901 - np.rint(20e-6 * (t - BASE)).astype(np.int64),
              '/c': lambda t: t + 40 * MS}
    events = {topic: thinned(truth, 0.5, seed=3 + i) for i, topic in enumerate(clocks)}
    now = int(truth[0])
    next_step = now + 500 * MS
    while now < int(truth[0]) + seconds * S:
        for topic, ev in events.items():
            part = ev[(ev >= now) & (ev < now + 20 * MS)]
            if part.size:
                receipt = int(part[-1]) + int(rng.integers(1 * MS, 4 * MS))
                times = clocks[topic](part)
                if by_bins:
                    sync.add_bins(topic, MessageBins.of(times, receipt_ns=receipt, grid_ns=sync.params.grid_ns))
                else:
                    sync.add(topic, times, receipt)
        now += 20 * MS
        if now >= next_step:
            sync.step(now)
            next_step += 500 * MS


def test_an_estimator_fed_counts_locks_exactly_as_one_fed_times():
    by_times = Engine(['/a', '/b', '/c'], reference='/a')
    by_bins = Engine(['/a', '/b', '/c'], reference='/a')
    feed(by_times, by_bins=False)
    feed(by_bins, by_bins=True)
    for topic in ('/b', '/c'):
        a, b = by_times.status(topic), by_bins.status(topic)
        assert a.state.value == b.state.value == 'locked'
        assert a.correction == b.correction
        assert (a.events, a.windows_accepted) == (b.events, b.windows_accepted)
