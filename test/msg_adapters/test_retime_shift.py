"""The live evt3 retimer's shift (``_kernels.c`` ``shift_of``, mode 1) against the Python formula of
``ClockCorrection.apply``, through a numpy oracle (``ReferenceRetimer``): not against another path through
the same C ``shift_of``, as the byte-for-byte tests of ``test_restamp_kernels.py`` compare."""
from __future__ import annotations

import numpy as np
import pytest

from evsync_ros.core.clock import ClockCorrection
from evsync_testing.messages import packet_bytes
from evsync_testing.reference import ReferenceRetimer
from msg_adapters.definitions import EVENT_PACKET
from msg_adapters.event_packet import parse_event_packet
from msg_adapters.evt3 import Evt3Retimer, encode_evt3
from msg_adapters.registry import Restamper

NS = 1_000_000_000
A = 1_700_000_000 * NS


def _payload(t_us):
    n = len(t_us)
    return encode_evt3(np.asarray(t_us, np.int64), np.arange(n) % 8, np.arange(n) % 8, np.ones(n))


def _live_shift(corr, in_anchor, out_anchor):
    """A live stream's shift of sensor time u (us), as the Python formula gives it."""
    def live_shift(u):
        return (corr.apply(u * 1000 + in_anchor) - out_anchor + 500) // 1000 - u
    return live_shift


def _want(payload, corr, in_anchor, out_anchor):
    return ReferenceRetimer(0.0).retime(payload, shift_us=_live_shift(corr, in_anchor, out_anchor))


def _got(payload, corr, in_anchor, out_anchor):
    out = Evt3Retimer(0.0).retime_to(payload, in_anchor_ns=in_anchor, offset_ns=corr.offset_ns,
                                     skew_ppm=corr.skew_ppm, anchor_ns=corr.anchor_ns, out_anchor_ns=out_anchor)
    return bytes(payload) if out is None else out


def test_a_live_retime_does_not_take_the_shift_of_the_call_before():
    """evt3_retime's Shift is on the stack: what one call leaves there is not the next call's shift."""
    from msg_adapters import _kernels
    payload = bytes(_payload(5_000 + np.arange(20) * 100))
    corrs = [ClockCorrection(offset_ns=3_000_000), ClockCorrection(offset_ns=7_000_000)]
    wants = [_want(payload, c, A, A) for c in corrs]
    init = np.array([-1, -1, 0, -1, 0, 0], np.int64)
    states = [init.copy(), init.copy()]
    f = _kernels.evt3_retime
    # back to back, little Python between (as a stream's messages come through the Python restamp path)
    got0 = f(payload, states[0], 1, 0.0, A, 3_000_000, A, A)
    got1 = f(payload, states[1], 1, 0.0, A, 7_000_000, A, A)
    assert [got0, got1] == wants


@pytest.mark.parametrize('skew_ppm', [1000.0, -1000.0, 62_500.0])
def test_a_live_retime_follows_the_skew_within_a_payload(skew_ppm):
    """rint(k (t - anchor)) steps many times inside one payload, the shift with it: a cached shift must move
    with every step (the numpy oracle computes each time's shift from the Python formula)."""
    corr = ClockCorrection(offset_ns=1_234_567, skew_ppm=skew_ppm, anchor_ns=A - 3)
    payload = _payload(5_001 + np.arange(3000) * 7)  # 21 ms of sensor time: r moves 21 us per ms at 1000 ppm
    assert _got(payload, corr, A, A + 1_234_567) == _want(payload, corr, A, A + 1_234_567)


def test_a_restamped_evt3_stream_carries_the_formula_s_times():
    """Through Restamper (the C whole-message call), each packet's words against the oracle: independent of
    the Python path, which shares shift_of with it."""
    corr = ClockCorrection(offset_ns=2_000_000, skew_ppm=1000.0, anchor_ns=A)
    r = Restamper(EVENT_PACKET)
    start = 5_000
    for i in range(4):
        t = start + 20_000 * i + np.arange(2000) * 10
        raw = packet_bytes('evt3', _payload(t), seq=i, stamp_ns=A + 1000 * (int(t[0]) - start))
        out = parse_event_packet(bytes(r.restamp(raw, corr)))
        _, anchors = r.packets.retimer
        in_anchor, out_anchor = int(anchors[1]), int(anchors[3])
        ref = ReferenceRetimer(0.0)
        # the oracle walks the stream from its start, as the restamper's state has
        for j in range(i + 1):
            tj = start + 20_000 * j + np.arange(2000) * 10
            want = ref.retime(_payload(tj), shift_us=_live_shift(corr, in_anchor, out_anchor))
        assert bytes(out.events) == want


def test_a_live_retime_rounds_a_tie_on_the_shift_s_boundary_to_even():
    """k = 1/16 with t - anchor = 8 mod 16 at every even u: r = rint(k (t - anchor)) is a tie m + 1/2 with m a
    multiple of 250 for u a multiple of 4; out_anchor = in_anchor + offset - 499 puts those ties exactly where the
    shift steps (a_in + off + r - a_out + 500 = r + 999): half-up rounding there writes a time 1 us late."""
    assert 62_500.0 * 1e-6 == 1 / 16
    corr = ClockCorrection(offset_ns=0, skew_ppm=62_500.0, anchor_ns=A - 8)
    payload = _payload(5_000 + np.arange(400))
    assert _got(payload, corr, A, A - 499) == _want(payload, corr, A, A - 499)
