"""What a consumer of evsync_node's outputs sees, decoding them as consumers do (issue 22).

An evt3 consumer (event_camera_codecs, and our decoder) anchors a stream's sensor time once, at the
first packet it receives: whatever clock that packet puts the stream on, the stream stays on. With
the shipped defaults (``before_lock: coarse``) a camera whose clock is on another epoch goes out on
the reference's clock from its first message, within the arrival-time offset's milliseconds, and
within the estimator's accuracy from the lock on. The node runs in this process, fed a simulated rig
at its recorded times, its outputs collected through real DDS (``nodefaults.Replay``)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy is installed by ./dev setup')

from evsync_testing import nodefaults
from msg_adapters.event_packet import EventPacketDecoder

S = 1_000_000_000
COARSE_NS = 10_000_000
"""Before the lock, the arrival-time offset: milliseconds."""


@pytest.mark.parametrize(('seed', 'by_s'), [(5, 1000.0), (6, -1000.0), (7, 3.3)])
def test_an_evt3_camera_on_another_epoch_reaches_its_consumers_on_the_reference_clock(tmp_path, seed, by_s):
    truth = nodefaults.sim_bag(tmp_path / 'rig', seconds=16, seed=seed)
    cam = nodefaults.cameras(truth)['evt3']
    by = int(by_s * S)
    fed = nodefaults.clock_jump(nodefaults.read_messages(tmp_path / 'rig'), cam, 0.0, by)  # all its stamps
    replay = nodefaults.Replay(truth)  # the shipped defaults but the test's QoS
    try:
        replay.feed(fed)
        sent = [(stamp, raw) for topic, stamp, raw in fed if topic == cam]
        out = replay.outputs[cam]
        assert len(out) == len(sent)
        locked_at = next(now for now, d in replay.diagnostics if d.get(cam, {}).get('state') == 'locked')
        assert replay.last(cam)['state'] == 'locked'
    finally:
        replay.close()
    want = nodefaults.truth_correction(next(c for c in truth['cameras'] if c['topic'] == cam))
    source, consumer = EventPacketDecoder(), EventPacketDecoder()  # each anchors at its first packet
    before: list[float] = []
    after: list[float] = []
    for (stamp, raw_in), raw_out in zip(sent, out):
        t_in, t_out = source.decode(raw_in)[1].t, consumer.decode(raw_out)[1].t
        if t_in.size:
            error = int(np.abs(t_out - want.apply(t_in - by)).max())
            (after if stamp > locked_at else before).append(error)
    assert after and before
    assert max(before) < COARSE_NS, f'before the lock, events {max(before) / 1e6:.1f} ms from the truth'
    assert max(after) < nodefaults.TOLERANCE_NS, f'after the lock, events {max(after) / 1e3:.0f} us from the truth'
