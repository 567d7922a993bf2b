"""A camera process's counts: the wire form round-trips, bad batches are named, and an estimator fed
counts tracks exactly as one fed the event times."""

import numpy as np
import pytest

from evsync_ros.core.bins import BinnedStream
from evsync_ros.core.counts import MessageBins
from evsync_ros.core.engine import Engine
from evsync_ros.core.engine.feed import add_counted
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


def counted(times, grid):
    """(k0, counts) of a message as the one C call counts it (None: it spans more than 4096 bins)."""
    k0 = int(times.min()) // grid
    dense = np.bincount(times // grid - k0).astype(np.int32)
    return k0, dense if dense.size <= 4096 else None


def feed(sync, *, by_bins, seconds=28, corrupt=False):
    """Three cameras seeing one scene (offsets +2.3 s at 20 ppm and -40 ms against /a) in 20 ms
    messages arriving 1-4 ms after their last event, stepped every 500 ms; each message given to
    ``sync`` as its times, or (``by_bins``) as its counts ('counted': its times with its counts, as
    the node's message path gives them: ``feed.add_counted``); with ``corrupt``, one in 97 messages
    of /b has one time 300 s off, and one in 89 of /c all its times 30 s off."""
    truth = bursty(seconds + 2, seed=3, rate=60.0)
    rng = np.random.default_rng(103)
    clocks = {'/a': lambda t: t, '/b': lambda t: t - 2_345_678_901 - np.rint(20e-6 * (t - BASE)).astype(np.int64),
              '/c': lambda t: t + 40 * MS}
    events = {topic: thinned(truth, 0.5, seed=3 + i) for i, topic in enumerate(clocks)}
    now = int(truth[0])
    next_step = now + 500 * MS
    sent: dict[str, int] = {}
    while now < int(truth[0]) + seconds * S:
        for topic, ev in events.items():
            part = ev[(ev >= now) & (ev < now + 20 * MS)]
            if part.size:
                receipt = int(part[-1]) + int(rng.integers(1 * MS, 4 * MS))
                times = clocks[topic](part)
                if corrupt and topic == '/b' and rng.integers(97) == 0:
                    times[times.size // 3] += 300 * S
                sent[topic] = sent.get(topic, 0) + 1
                if corrupt and topic == '/c' and sent[topic] % 89 == 50:
                    times = times + 30 * S  # a whole message off its arrival line: its events far
                if by_bins == 'counted':
                    k0, counts = counted(times, sync.params.grid_ns)
                    if counts is None:
                        sync.add(topic, times, receipt)
                    else:
                        add_counted(sync, topic, times, receipt, lo=int(times.min()), hi=int(times.max()),
                                    mid=int(times[times.size // 2]), k0=k0, counts=counts)
                elif by_bins:
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


@pytest.mark.parametrize('corrupt', [False, True], ids=['clean', 'corrupt times'])
def test_an_estimator_fed_counted_messages_is_the_one_fed_times(corrupt):
    """The node's message path: each message's times with its counts (``feed.add_counted``) leave the
    estimator exactly as the times alone do: its bins, counters and lock."""
    by_times = Engine(['/a', '/b', '/c'], reference='/a')
    by_counts = Engine(['/a', '/b', '/c'], reference='/a')
    feed(by_times, by_bins=False, seconds=14, corrupt=corrupt)
    feed(by_counts, by_bins='counted', seconds=14, corrupt=corrupt)
    for topic in ('/a', '/b', '/c'):
        a, b = by_times.stream(topic), by_counts.stream(topic)
        assert (a.bins.events, a.bins.far_events, a.far_events, a.events) == \
            (b.bins.events, b.bins.far_events, b.far_events, b.events)
        assert (a.bins.first_ns, a.bins.last_ns, a.bins.origin_ns) == \
            (b.bins.first_ns, b.bins.last_ns, b.bins.origin_ns)
        hi = a.bins.last_ns - (a.bins.last_ns - a.bins.origin_ns) % GRID
        lo = hi - 5 * S
        n = int((hi - lo) // GRID)
        assert np.array_equal(a.bins.snapshot(lo, hi).counts(lo, GRID, n), b.bins.snapshot(lo, hi).counts(lo, GRID, n))
    for topic in ('/b', '/c'):
        said, also = by_times.status(topic), by_counts.status(topic)
        assert said.correction == also.correction and said.state == also.state
    if corrupt:
        assert by_times.stream('/b').far_events > 0 and 0 < by_times.stream('/c').far_events < 1000
