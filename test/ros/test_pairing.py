"""Joining restamped topics over DDS (issue 39): the recipe of docs/node.md, "Pairing restamped
topics". Two cameras whose packets fall 3 ms apart (the real DAVIS346 stream, and a copy on another
clock cut into packets 3 ms later), through evsync_node seeded with the copy's known offset, are
paired on header.stamp by an approximate-time pairing with the QoS the outputs need and a slop of
half a packet period. message_filters has no PyPI wheel for Jazzy (docs/node.md), so the pairing is
written here; in a ROS install it is message_filters' ApproximateTimeSynchronizer."""

import functools
from collections import deque

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy is installed by ./dev setup')

from rclpy.qos import QoSProfile, ReliabilityPolicy

from evsync_ros.ros.messages import message_class
from evsync_testing import nodefaults
from evsync_testing.copies import davis_rephased
from msg_adapters.cdr import read_stamp
from msg_adapters.definitions import DVS_EVENT_ARRAY
from msg_adapters.registry import decoder_for

MS = 1_000_000
PERIOD_NS = 10 * MS
"""libcaer_driver's packets in the real recording: 10 ms."""
PHASE_NS = 3 * MS


class Pairing:
    """Two streams paired on header.stamp, each message with the other stream's nearest within
    ``slop``, decided once the other stream has a message past it (an approximate-time policy)."""

    def __init__(self, slop_ns: int) -> None:
        self.slop = slop_ns
        self.queues: tuple[deque[int], deque[int]] = (deque(), deque())
        self.pairs: list[tuple[int, int]] = []

    def add(self, which: int, raw: bytes) -> None:
        self.queues[which].append(read_stamp(raw))
        while all(self.queues):
            first = 0 if self.queues[0][0] <= self.queues[1][0] else 1
            head, other = self.queues[first][0], self.queues[1 - first]
            if other[-1] < head:
                return  # the other stream's nearest may be still to come
            near = min(range(len(other)), key=lambda j: abs(other[j] - head))
            self.queues[first].popleft()
            if abs(other[near] - head) <= self.slop:
                pair = (head, other[near])
                self.pairs.append(pair if first == 0 else pair[::-1])
                for _ in range(near + 1):
                    other.popleft()


BEST_EFFORT = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
"""The recipe's subscriptions to outputs offered best effort (the default): a second of packets."""
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
"""The recipe's subscriptions to outputs offered reliable (``output_reliability: reliable``)."""
MESSAGE_FILTERS_DEFAULT = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
"""What message_filters.Subscriber asks when given no qos_profile."""


@pytest.mark.parametrize('reliability', ['reliable', None], ids=['reliable', 'default'])
def test_restamped_topics_pair_over_dds_with_the_recipe_s_qos_and_slop(tmp_path, real_data, reliability):
    """Issue 52: with ``output_reliability: reliable`` a subscriber with message_filters' own defaults
    (reliable, depth 10) receives every output (given the time each takes at the recording's pace, as
    the replay feeds the node as fast as it can), and the recipe pairs them; the default outputs (best
    effort, docs/node.md says why) pair with a best-effort subscription, and a default subscriber
    gets nothing of them."""
    copies = davis_rephased(real_data, phase_ns=PHASE_NS)
    truth = {'reference': copies.reference,
             'cameras': [{'topic': t, 'encoding': 'dvs' if m == DVS_EVENT_ARRAY else 'evt3'}
                         for t, m in copies.types.items()]}
    chosen = {} if reliability is None else {'output_reliability': reliability}
    replay = nodefaults.Replay(truth, listen_qos=BEST_EFFORT, qos='sensor_data', **chosen,
                               offsets_file=str(copies.write_offsets(tmp_path / 'offsets.json')))
    pairing = Pairing(slop_ns=PERIOD_NS // 2)
    plain: list[bytes] = []
    try:
        replay.node.estimator.sync.freeze(True)  # the copy's known offset stays
        recipe = RELIABLE if reliability == 'reliable' else BEST_EFFORT
        for which, topic in enumerate(copies.topics()):
            replay.listener.create_subscription(message_class(copies.types[topic]), topic + '/synced',
                                                functools.partial(pairing.add, which), recipe, raw=True)
        # message_filters' default subscriber, beside them
        replay.listener.create_subscription(message_class(copies.types[copies.reference]),
                                            copies.reference + '/synced', plain.append, MESSAGE_FILTERS_DEFAULT,
                                            raw=True)
        ref, copy = (replay.node.path.streams[t].publisher for t in copies.topics())
        matched = 3 if reliability == 'reliable' else 2  # best effort: the default one never matches
        replay.wait(lambda: ref.get_subscription_count() >= matched and copy.get_subscription_count() >= 2,
                    'subscribers matched')
        assert ref.get_subscription_count() == matched

        def kept_up() -> None:  # the recording's pace (a packet each 10 ms) lets depth 10 keep up; the replay's not
            if reliability == 'reliable':
                sent = replay.node.path.streams[copies.reference].published
                replay.wait(lambda: len(plain) >= sent, 'the default subscriber keeping up')

        replay.feed(sorted(copies.messages, key=lambda m: m[1]), after=kept_up)
        n = len(copies.of(copies.reference))
        replay.wait(lambda: len(pairing.pairs) >= n - 1, 'pairs')
        out_ref = replay.outputs[copies.reference]
    finally:
        replay.close()
    # what the pairs must be: each reference packet with the copy's packet that starts 3 ms after it
    times = decoder_for(copies.types[copies.reference])
    firsts = [int(times.decode(raw)[1].t[0]) for raw in copies.of(copies.reference)]
    t = np.concatenate([decoder_for(copies.types[copies.reference]).decode(raw)[1].t
                        for raw in copies.of(copies.reference)])
    expected = [(s, int(t[np.searchsorted(t, s + PHASE_NS)])) for s in firsts]
    assert pairing.pairs == expected[:len(pairing.pairs)] and len(pairing.pairs) >= n - 1
    assert all(0 < b - a <= PERIOD_NS // 2 for a, b in pairing.pairs)
    if reliability is None:
        assert not plain  # "incompatible QoS": nothing is sent to it
    else:
        assert len(plain) == n and plain == out_ref, f'{len(plain)} of {n} outputs reached a default subscriber'

