"""Simulated bags: the truth JSON maps what the adapters decode onto the reference timeline."""

import json

import numpy as np
import pytest

from evsync_ros.bag.estimate import read_event_times
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.errors import BagError
from evsync_ros.sim.pixelsim import camera_clock, preset, simulate
from evsync_ros.sim.simbag import write_rig


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_truth_maps_decoded_times_onto_the_reference_clock(tmp_path, storage):
    rig = preset('drift', seed=2, duration_s=6)
    events = simulate(rig)
    truth = write_rig(rig, events, tmp_path / 'bag', storage=storage)
    assert json.loads((tmp_path / 'bag.truth.json').read_text()) == truth
    times, reports = read_event_times(tmp_path / 'bag')
    assert {t: r.events for t, r in reports.items()} == {t: e.t.size for t, e in events.items()}
    assert all(not r.anomalies and not r.undecodable for r in reports.values())
    ref = rig.camera(rig.reference)
    # where the reference's own decoded timeline puts true time t: its first event fixes the constant
    ref_shift = int(times[rig.reference][0] - events[rig.reference].t[0])
    for cam in truth['cameras']:
        c = ClockCorrection(offset_ns=cam['offset_ns'], skew_ppm=cam['skew_ppm'], anchor_ns=cam['anchor_ns'])
        on_ref = c.apply(times[cam['topic']])
        expected = camera_clock(ref, events[cam['topic']].true_t) + ref_shift
        assert np.abs(on_ref - expected).max() <= 2_000  # microsecond evt3 time words
    assert any(abs(c['skew_ppm']) > 1 for c in truth['cameras'])


def test_refuses_to_overwrite_and_leaves_nothing_on_failure(tmp_path):
    rig = preset('same-model', seed=0, duration_s=2)
    events = simulate(rig)
    (tmp_path / 'bag').mkdir()
    with pytest.raises(BagError, match='refusing to overwrite'):
        write_rig(rig, events, tmp_path / 'bag')
    broken = dict(events)
    broken.pop(rig.cameras[1].topic)
    with pytest.raises(KeyError):
        write_rig(rig, broken, tmp_path / 'other')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag']  # no partial bag, no truth
