"""Binning at the decoders' pace: a stream holds its chunks and counts them together (``BinnedStream.flush``),
which must give, at every moment, exactly what binning each chunk as it came gives: the same blocks,
counts, far and late events, on fuzzed times (out of order, far-apart epochs, corrupt) and on the real
recordings. And the arrival line's medians, taken without numpy, are numpy's to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from evsync_ros.core import bins as bins_module
from evsync_ros.core.bins import BLOCK_BINS, BinnedStream, SortedTimes
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine.arrival import _median
from evsync_testing.fuzz import FUZZ, no_hang

S = 1_000_000_000
EPOCHS = (0, 7 * S, 1_763_700_000 * S, 2**61, -(2**40))
"""Where a chunk's times lie: sensor clocks near 0, host epochs, the far end of int64 time."""


@st.composite
def chunk(draw) -> np.ndarray:
    """One message's times: around an epoch, sorted or shuffled, now and then a corrupt time."""
    epoch = draw(st.sampled_from(EPOCHS)) + draw(st.integers(0, 40 * S))
    n = draw(st.integers(0, 400))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    span = draw(st.sampled_from([10**6, 10**8, 10 * S, 100 * S]))
    t = epoch + rng.integers(0, span, n)
    if draw(st.booleans()):
        t = np.sort(t)
    if n and draw(st.integers(0, 9)) == 0:
        t[rng.integers(0, n)] = draw(st.sampled_from([2**62, -(2**62), 2**63 - 1, 0]))
    return t.astype(np.int64)


operations = st.lists(st.one_of(st.tuples(st.just('add'), chunk()),
                                st.tuples(st.just('drop'), st.integers(-2 * S, 60 * S))), max_size=40)


def same(held: BinnedStream, once: BinnedStream) -> None:
    """Everything a reader sees of the two streams, equal (``held`` flushed last, so that the
    scalars are compared before anything forced its chunks into the blocks)."""
    assert (held.nbytes, held.events, held.far_events, held.first_ns, held.last_ns, held.origin_ns) == \
        (once.nbytes, once.events, once.far_events, once.first_ns, once.last_ns, once.origin_ns)
    assert held.dropped_late == once.dropped_late
    held.flush()
    assert sorted(held._blocks) == sorted(once._blocks)
    for b, block in once._blocks.items():
        np.testing.assert_array_equal(held._blocks[b], block)


def binned_at_once(grid_ns: int, correction: ClockCorrection | None = None) -> BinnedStream:
    """A stream that counts every chunk as it comes (what BinnedStream did before it held chunks)."""
    stream = BinnedStream(grid_ns=grid_ns, correction=correction)
    add = stream.add

    def add_and_count(times, **kw):
        add(times, **kw)
        stream.flush()

    stream.add = add_and_count  # type: ignore[method-assign]
    return stream


@FUZZ
@given(ops=operations, grid=st.sampled_from([100_000, 50_000, 1_000_000]), skew=st.sampled_from([0.0, 37.5]))
def test_held_chunks_count_as_each_chunk_binned_as_it_came(ops, grid, skew):
    correction = ClockCorrection(offset_ns=0, skew_ppm=skew, anchor_ns=EPOCHS[2]) if skew else None
    held, once = BinnedStream(grid_ns=grid, correction=correction), binned_at_once(grid, correction)
    with no_hang(30):
        for what, arg in ops:
            if what == 'add':
                held.add(arg)
                once.add(arg)
                assert held.nbytes == once.nbytes  # blocks are made as a chunk comes, not as it is counted
            elif once.first_ns is not None:
                held.drop_before(once.first_ns + arg)
                once.drop_before(once.first_ns + arg)
        same(held, once)


def test_many_messages_are_counted_together_and_read_alike():
    # 1 ms messages of a busy camera, a few out of order: held until read, then one bincount
    rng = np.random.default_rng(5)
    t = np.sort(rng.integers(0, 20 * S, 2_000_000)) + EPOCHS[2]
    messages = np.array_split(t, 20_000)
    messages[100], messages[101] = messages[101], messages[100]
    held = BinnedStream(grid_ns=100_000)
    for m in messages:
        held.add(m)
    assert held._pending  # counted only when read (or when PENDING_EVENTS wait)
    whole = SortedTimes(t)
    for start, bin_ns, n in [(int(t[0]) - 10**6, 1_000_000, 21_000), (held.origin_ns + 12_345 * 100_000, 100_000, 7)]:
        np.testing.assert_array_equal(held.counts(start, bin_ns, n), whole.counts(start, bin_ns, n))
    blocks = -(-(int(t[-1]) - int(t[0]) + 1) // (100_000 * BLOCK_BINS))
    assert not held._pending and held.nbytes == blocks * 4 * BLOCK_BINS


def real_messages(bag):
    """Each event topic's messages' times, in bag order (as ``evsync estimate`` decodes them)."""
    from evsync_ros.bag.events import TopicReport, decoded, event_topics
    from evsync_ros.bag.reader import BagReader

    with BagReader(bag) as reader:
        chosen = event_topics(reader, bag, None)
        reports = {t: TopicReport(m) for t, m in chosen.items()}
        return [(topic, t) for topic, t, _ in decoded(reader, chosen, reports)]


@pytest.mark.parametrize('recording', ['evt3_sqlite3', 'libcaer_cmp_mcap', 'evk4_hd', 'dvs128_stereo/fan'])
def test_real_recordings_count_alike_held_or_binned_as_they_came(real_data, recording):
    messages = real_messages(real_data / recording)
    topics = sorted({topic for topic, _ in messages})
    held = {t: BinnedStream(grid_ns=100_000) for t in topics}
    once = {t: binned_at_once(100_000) for t in topics}
    whole = {t: SortedTimes(np.sort(np.concatenate([m for topic, m in messages if topic == t]))) for t in topics}
    for i, (topic, t) in enumerate(messages):
        held[topic].add(t)
        once[topic].add(t)
        if i % 64 == 63:  # as the engine steps: every 64 messages, bins 2 s behind the newest freed
            s = once[topic]
            if i % 256 == 255 and s.last_ns is not None:
                held[topic].drop_before(s.last_ns - 2 * S)
                s.drop_before(s.last_ns - 2 * S)
    for topic in topics:
        assert held[topic].events == whole[topic].times.size
        same(held[topic], once[topic])
    # and without freeing, the counts of every bin are the whole recording's
    for topic in topics:
        fresh = BinnedStream(grid_ns=100_000)
        for name, t in messages:
            if name == topic:
                fresh.add(t)
        n = (fresh.last_ns - fresh.origin_ns) // 100_000 + 1
        np.testing.assert_array_equal(fresh.counts(fresh.origin_ns, 100_000, n),
                                      whole[topic].counts(fresh.origin_ns, 100_000, n))


def test_estimates_of_a_real_rig_are_the_same_counted_per_message(real_data, monkeypatch):
    from evsync_ros.bag.estimate import estimate_bag

    bag = real_data / 'dvs128_stereo' / 'fan'
    held = estimate_bag(bag)
    monkeypatch.setattr(bins_module, 'PENDING_EVENTS', 0)  # every chunk counted as it comes
    once = estimate_bag(bag)
    assert held.rig.as_json() == once.rig.as_json()
    assert (held.passes, held.late_events, held.far_events, held.peak_bin_bytes) == \
        (once.passes, once.late_events, once.far_events, once.peak_bin_bytes)


@FUZZ
@given(values=st.lists(st.one_of(st.floats(allow_nan=False, allow_infinity=False, width=64),
                                 st.integers(-(2**53), 2**53).map(float), st.sampled_from([0.0, -0.0])),
                       min_size=1, max_size=40))
def test_the_arrival_line_medians_are_numpys_to_the_bit(values):
    assert _median(values).hex() == float(np.median(np.array(values, np.float64))).hex()
