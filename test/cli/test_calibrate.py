"""Verify, calibrate, go cable-free (simulator only: the truth is known): calibrated on one recording
of a two-make rig with a pulse wired to both cameras, a second recording of the same rig, with no
triggers, comes out within the calibration's error of the truth; without it, off by the makes' lag."""

from __future__ import annotations

import json
import math

from evsync_ros.cli import main as cli
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.sim.pixelsim import parse_make, preset, simulate
from evsync_ros.sim.simbag import write_rig

MAKE = 'lowpass-us=3000'
"""Make B's photoreceptor: 3 ms, ten times make A's, at 100 px/s a lag of about 2.3 ms."""


def _recording(tmp_path, *, seed: int, triggers_hz: float):
    rig = preset('two-makes-slow', seed=seed, duration_s=20, make=parse_make(MAKE), triggers_hz=triggers_hz,
                 speed_px_s=100)
    bag = tmp_path / f'rig-{seed}'
    return bag, write_rig(rig, simulate(rig), bag)


def _error_ns(doc: dict, truth: dict) -> tuple[int, float]:
    """Make B's estimate minus the truth at its anchor, and its stated error."""
    c = doc['cameras'][1]
    t = next(x for x in truth['cameras'] if x['topic'] == c['topic'])
    true = ClockCorrection(offset_ns=t['offset_ns'], skew_ppm=t['skew_ppm'], anchor_ns=t['anchor_ns'])
    return c['offset_ns'] - (true.apply_one(c['anchor_ns']) - c['anchor_ns']), c['uncertainty_ns']


def test_calibrated_once_a_rig_without_triggers_comes_out_right(tmp_path, capsys):
    wired, _ = _recording(tmp_path, seed=1, triggers_hz=5)
    lat = tmp_path / 'lat.json'
    # exit 1: verified, and outside the estimate's stated error (what calibrating is for)
    assert cli.main(['verify', str(wired), '--reference', '/make_a/events', '--save-latencies', str(lat)]) == 1
    doc = json.loads(lat.read_text())
    latency, cal_se = doc['latencies_ns']['/make_b/events'], doc['se_ns']['/make_b/events']
    assert 1_500_000 < latency < 3_500_000  # make B's envelope lags make A's by the makes' difference
    free, truth = _recording(tmp_path, seed=2, triggers_hz=0)
    capsys.readouterr()
    assert cli.main(['estimate', str(free), '--reference', '/make_a/events', '--json']) == 0
    before, stated = _error_ns(json.loads(capsys.readouterr().out), truth)
    assert cli.main(['estimate', str(free), '--reference', '/make_a/events', '--latencies', str(lat), '--json']) == 0
    after, _ = _error_ns(json.loads(capsys.readouterr().out), truth)
    print(f'lag {latency / 1e6:.3f} +- {cal_se / 1e6:.3f} ms; error {before / 1e6:+.3f} ms (stated {stated / 1e6:.3f}) '
          f'before, {after / 1e6:+.3f} ms after')
    assert abs(before) > 5 * stated  # without it: off by the makes' lag, beyond what the estimate states
    # with it: within the calibration's error: 3 of its standard errors, with the second recording's
    # own scatter about the lag, as large again (the same rig, as many windows)
    assert abs(after) <= 3 * math.hypot(cal_se, cal_se), (after, cal_se)
