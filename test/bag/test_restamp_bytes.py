"""What ``restamp_bag`` writes stays what it wrote before its writes were made faster, byte for byte.

Each real recording is restamped with fixed corrections (an offset, and a drift that rewrites evt3's
time words and every EventArray event's time) into each output storage, and the output's topics
(type, definition, hash, serialization, QoS or latching) and messages (topic, record time, bytes, in
the order a reader gives them) are hashed. The expected digests were computed from the outputs of
``restamp_bag`` as of commit cbbef27, before the writer batched its writes: a change to any byte of
any message, to a record time or to the order fails here. (The provenance in a rosbag2's metadata
holds the time of writing and the input's path, so it is not part of the digest.)"""

from __future__ import annotations

import pytest

from evsync_ros.bag.restamp import restamp_bag
from evsync_ros.core.clock import ClockCorrection
from evsync_testing.digest import bag_digest

EVT3 = '/event_camera/events'
CASES = {
    # (recording, reference, {topic: correction})
    'evt3_sqlite3': (EVT3, {EVT3: ClockCorrection(offset_ns=-2_000_000, skew_ppm=80.0,
                                                  anchor_ns=1_700_000_000_000_000_000)}),
    'libcaer_cmp_mcap': (EVT3, {EVT3: ClockCorrection(offset_ns=1_500_000_000)}),
    'dvs128_stereo/fan': ('/right/events', {'/left/events': ClockCorrection(offset_ns=37_400_000, skew_ppm=-60.0,
                                                                             anchor_ns=1_000_000_000)}),
}
OUTPUTS = {'sqlite3': 'out', 'mcap': 'out', 'ros1': 'out.bag'}
EXPECTED = {
    'evt3_sqlite3': ('0890222a0913cfb220d35eccf9c07defa38ff8eea9ea4888754a5651add11b73',
                     '1d0b528402f44da8fe521007621e266f87be1ba807ad04b69fda6c7500dccc27'),
    'libcaer_cmp_mcap': ('e72d0abc9b0d6a61abb3c6b0b434198bf6af006738a7c741123ee711bd9a2f7d',
                         '80032e9401dce0c356ff788569a96cf6e77e6bea3f2d29d75ff4f9a3da879dfd'),
    'dvs128_stereo/fan': ('0f52821c8c66643be2d4e4751d8a5ab0564efe00039ae5adcef7ec7c16fc04ee',
                          'e5c07471d84d2954a32a40a6169147af66f8fa4871b5ac1a3378f377bc554dce'),
}
"""Per recording, the digest of its rosbag2 outputs (sqlite3 and mcap hold the same) and of its ROS 1 output."""


@pytest.mark.parametrize('storage', list(OUTPUTS))
@pytest.mark.parametrize('name', list(CASES))
def test_restamped_bytes_are_unchanged(tmp_path, real_data, name, storage):
    reference, corrections = CASES[name]
    out = tmp_path / OUTPUTS[storage]
    rep = restamp_bag(real_data / name, out, corrections=corrections, reference=reference,
                      storage=None if storage == 'ros1' else storage)
    assert rep.bad == 0 and sum(t.restamped for t in rep.topics.values()) > 0
    assert bag_digest(out) == EXPECTED[name][storage == 'ros1']
