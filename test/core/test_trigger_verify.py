"""A density estimate against trigger edges (core.triggers): which pulse, the offset the edges give,
the estimate's error against them, and what cannot be verified, on edge trains made here."""

from __future__ import annotations

import numpy as np
import pytest

from evsync_ros.core.results import CameraFit, WindowFit
from evsync_ros.core.triggers import Edges, Verdict, ambiguous, edge_line, match, period_ns, verify

NS = 1_000_000_000
OFFSET = 3_456_789_012  # what the edges must give: camera time + OFFSET = reference time


def train(hz: float, seconds: float, *, start_ns: int = 0, jitter_ns: int = 0, seed: int = 0) -> Edges:
    """A square wave's edges (rising, falling at 30 % duty) from ``start_ns``."""
    period = round(NS / hz)
    rises = start_ns + np.arange(round(seconds * hz), dtype=np.int64) * period
    t = np.sort(np.concatenate([rises, rises + round(0.3 * period)]))
    value = np.tile(np.array([1, 0], np.uint8), rises.size)
    t = t + np.random.default_rng(seed).integers(-jitter_ns, jitter_ns + 1, t.size)
    return Edges(t.astype(np.int64), value)


def camera(offset_ns: int, *, se_ns: float = 50_000.0, accepted: bool = True, windows=()) -> CameraFit:
    return CameraFit(topic='/cam', offset_ns=offset_ns, skew_ppm=0.0, anchor_ns=0, accepted=accepted, cost=0.1,
                     confidence=0.9, window_ns=(0, 20 * NS), uncertainty_ns=se_ns, windows=tuple(windows))


def the_camera_of(ref: Edges, *, drop: slice | None = None, jitter_ns: int = 0) -> Edges:
    """The reference's edges on the camera's clock (OFFSET earlier), some missed."""
    keep = np.ones(ref.t.size, bool)
    if drop is not None:
        keep[drop] = False
    noise = np.random.default_rng(1).integers(-jitter_ns, jitter_ns + 1, ref.t.size)
    return Edges((ref.t - OFFSET + noise)[keep], ref.value[keep])


def test_the_estimate_s_error_is_what_it_is_off_from_the_edges():
    ref = train(5, 20, start_ns=NS)
    cam = the_camera_of(ref, drop=slice(10, 13), jitter_ns=2_000)
    off = 300_000  # the density estimate 0.3 ms off
    v = verify(camera(OFFSET + off, se_ns=50_000), ref, cam, reference='/ref')
    assert v.verdict is Verdict.VERIFIED and v.matched == cam.t.size
    assert v.trigger is not None and abs(v.trigger.offset_ns - OFFSET) < 1_000
    assert abs(v.error_ns - off) < 1_000
    assert v.within is False  # 0.3 ms is 6 of its stated 0.05 ms
    assert verify(camera(OFFSET + off, se_ns=150_000), ref, cam, reference='/ref').within is True


def test_a_window_s_error_is_its_offset_against_the_edges_at_its_middle():
    ref = train(5, 30, start_ns=NS)
    cam = the_camera_of(ref)
    windows = [WindowFit(ref_start_ns=k * 10 * NS, offset_ns=OFFSET + e, peak=0.9, confidence=0.9, accepted=a)
               for k, (e, a) in enumerate([(100_000, True), (-50_000, True), (9_000_000, False)])]
    v = verify(camera(OFFSET, windows=windows), ref, cam, reference='/ref')
    assert v.window_errors_ns == pytest.approx((100_000, -50_000), abs=10)  # the refused window left out
    stats = v.window_stats()
    assert stats is not None
    assert stats['mean_ns'] == pytest.approx(25_000, abs=10) and stats['max_abs_ns'] == pytest.approx(100_000, abs=10)


def test_a_drifting_camera_s_edges_give_its_skew():
    ref = train(10, 60, start_ns=NS)
    skew = 25e-6
    cam_t = np.rint((ref.t - OFFSET) / (1 + skew)).astype(np.int64)  # its clock slower by 25 ppm
    line = edge_line(ref.t, cam_t, anchor_ns=int(cam_t[0]))
    assert line.skew_ppm == pytest.approx(25, abs=0.01)
    assert np.abs(line.apply(cam_t) - ref.t).max() < 2


def test_a_pulse_faster_than_the_density_bound_is_ambiguous():
    ref = train(100, 5, start_ns=NS)  # 10 ms period
    assert period_ns(ref) == 10_000_000
    assert ambiguous(10_000_000, 250_000) and not ambiguous(200_000_000, 250_000)
    v = verify(camera(OFFSET), ref, the_camera_of(ref), reference='/ref')
    assert v.verdict is Verdict.AMBIGUOUS and v.reason == 'ambiguous: period 10 ms' and v.error_ns is None


def test_what_cannot_be_verified_says_why():
    ref = train(5, 20, start_ns=NS)
    none = Edges(np.empty(0, np.int64), np.empty(0, np.uint8))
    cam = the_camera_of(ref)
    assert verify(camera(OFFSET), none, cam, reference='/ref').reason == 'the reference has no trigger edges'
    assert verify(camera(OFFSET), ref, none, reference='/ref').reason == 'it has no trigger edges'
    assert verify(camera(OFFSET, accepted=False), ref, cam, reference='/ref').verdict is Verdict.NOT_ACCEPTED
    far = verify(camera(OFFSET + NS // 20), ref, the_camera_of(ref), reference='/ref')  # 50 ms off: half a 30 % pulse
    assert far.verdict is Verdict.VERIFIED and abs(far.error_ns - NS // 20) < 1_000  # still the right pulse
    lost = verify(camera(OFFSET + 7 * NS), ref, the_camera_of(ref), reference='/ref')  # edges after the reference's end
    assert lost.verdict is Verdict.UNMATCHED or lost.matched < 0.7 * ref.t.size


def test_a_reference_edge_claimed_twice_keeps_neither():
    ref = Edges(np.array([0, 1_000_000_000], np.int64), np.array([1, 1], np.uint8))
    cam = Edges(np.array([10, 20, 999_000_000], np.int64), np.array([1, 1, 1], np.uint8))
    from evsync_ros.core.clock import ClockCorrection
    c, r = match(ref, cam, ClockCorrection(), within_ns=1e8)
    assert c.tolist() == [2] and r.tolist() == [1]


def test_without_the_reference_s_edges_cameras_are_tied_to_the_best_known():
    """``tie``: the reference has no edges; /a (density 50 us) is the anchor and keeps its line, /b
    (density 200 us, 300 us off) takes /a's line and the edges between them; /c, no edges, as it is."""
    from dataclasses import replace

    from evsync_ros.core.triggers import edge_anchor, tie
    pulse = train(5, 20, start_ns=10 * NS, jitter_ns=1_000)  # on the reference's timeline
    a_off, b_off = 1_000_000_000, -2_000_000_000
    a = replace(camera(a_off + 40_000, se_ns=50_000.0), topic='/a')  # its density 40 us off
    b = replace(camera(b_off + 300_000, se_ns=200_000.0), topic='/b')
    c = replace(camera(5, se_ns=10.0), topic='/c')
    fits = {'/a': a, '/b': b, '/c': c}
    edges = {'/a': Edges(pulse.t - a_off, pulse.value), '/b': Edges(pulse.t - b_off, pulse.value),
             '/ref': Edges(np.empty(0, np.int64), np.empty(0, np.uint8))}
    assert edge_anchor(fits, edges, reference='/ref') == '/a'
    assert edge_anchor(fits, edges, reference='/ref', keep='/b') == '/b'  # held while it can be
    assert edge_anchor(fits, edges, reference='/ref', keep='/c') == '/a'  # /c has no edges
    assert tie(a, fits, edges, reference='/ref', anchor='/a') is a
    assert tie(c, fits, edges, reference='/ref', anchor='/a') is c
    tied = tie(b, fits, edges, reference='/ref', anchor='/a')
    assert tied.tied_to == '/a' and tied.edges > 100 and tied.density_offset_ns == b.offset_ns
    assert abs(tied.offset_ns - (b_off + 40_000)) < 1_000  # /a's error, and not its own 300 us
    assert 50_000 <= (tied.uncertainty_ns or 0) < 50_100
    assert tie(b, fits, edges, reference='/ref', anchor='/b') is b  # the anchor itself: as it is
    with_ref = {**edges, '/ref': pulse}
    assert edge_anchor(fits, with_ref, reference='/ref', keep='/a') == '/ref'  # the reference's edges first
    on_ref = tie(b, fits, with_ref, reference='/ref', anchor='/ref')
    assert on_ref.tied_to == '' and abs(on_ref.offset_ns - b_off) < 1_000
