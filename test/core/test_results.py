"""The result contract: keyword-only results, JSON out and back in, and the checks on what comes in."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from typing import Any

import pytest

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.errors import ParameterError, StreamError
from evsync_ros.core.results import CameraFit, RigFit, WindowFit, load_rig

CAM: dict[str, Any] = dict(topic='/b', offset_ns=-1_234_567_890_123, skew_ppm=12.5, anchor_ns=1_700_000_000_000_000_000,
           accepted=True, cost=0.02, confidence=0.61, window_ns=(10, 20))


def rig() -> RigFit:
    ref = CameraFit.reference_entry('/a', start_ns=10, window_ns=10)
    return RigFit(reference='/a', cameras=(ref, CameraFit(**CAM)))


def test_results_are_built_by_keyword_only():
    with pytest.raises(TypeError):
        CameraFit(*CAM.values())  # type: ignore[call-arg]
    with pytest.raises(TypeError):
        WindowFit(0, 0, 0.5, 0.5, True)  # type: ignore[call-arg]


def test_json_is_the_contract_byte_for_byte_and_reads_back():
    text = json.dumps(rig().as_json())
    # the fields of the first contract first, in their order; the fields added since after them
    assert text == ('{"reference": "/a", "cameras": [{"topic": "/a", "offset_ns": 0, "skew_ppm": 0.0, '
                    '"anchor_ns": 0, "accepted": true, "cost": 0.0, "confidence": 1.0, "window_ns": [10, 20], '
                    '"uncertainty_ns": 0.0, "skew_uncertainty_ppm": null, "reason": "", "windows_agreeing": 0, '
                    '"windows_total": 0, "spread_ns": 0.0, "prior": null, "prior_reason": ""}, '
                    '{"topic": "/b", "offset_ns": -1234567890123, "skew_ppm": 12.5, '
                    '"anchor_ns": 1700000000000000000, "accepted": true, "cost": 0.02, "confidence": 0.61, '
                    '"window_ns": [10, 20], "uncertainty_ns": null, "skew_uncertainty_ppm": null, "reason": "", '
                    '"windows_agreeing": 0, "windows_total": 0, "spread_ns": null, "prior": null, '
                    '"prior_reason": ""}]}')
    back = RigFit.from_json(json.loads(text))
    assert back == rig()
    want = ClockCorrection(offset_ns=CAM['offset_ns'], skew_ppm=12.5, anchor_ns=CAM['anchor_ns'])
    assert back.corrections['/b'] == want
    assert back.camera('/b').confidence == 0.61
    with pytest.raises(StreamError, match='/z'):
        back.camera('/z')


def test_a_hand_written_correction_needs_only_the_four_fields(tmp_path):
    path = tmp_path / 'hand.json'
    path.write_text(json.dumps({'reference': '/a', 'cameras': [
        {'topic': '/a', 'offset_ns': 0, 'skew_ppm': 0, 'anchor_ns': 0},
        {'topic': '/b', 'offset_ns': 5, 'skew_ppm': 1.5, 'anchor_ns': 7}]}))
    cam = load_rig(path).camera('/b')
    assert (cam.offset_ns, cam.skew_ppm, cam.anchor_ns, cam.accepted) == (5, 1.5, 7, True)
    assert math.isnan(cam.cost) and math.isnan(cam.confidence)


@pytest.mark.parametrize('change, said', [
    ({'reference': '/z'}, 'reference /z is not among'),
    ({'cameras': [{**CAM, 'topic': '/a', 'window_ns': [1, 2]}, {**CAM, 'offset_ns': 1.5, 'window_ns': [1, 2]}]},
     'must be an integer'),
    ({'cameras': [{**CAM, 'topic': '/a', 'window_ns': [1, 2]}, {**CAM, 'skew_ppm': 'nan', 'window_ns': [1, 2]}]},
     'not finite'),
    ({'cameras': [{**CAM, 'topic': '/a', 'window_ns': [1, 2]}, {**CAM, 'topic': '/a', 'window_ns': [1, 2]}]},
     'appears twice'),
    ({'cameras': 3}, 'not an evsync estimate'),
])
def test_what_is_not_the_contract_is_refused_naming_the_file(tmp_path, change, said):
    path = tmp_path / 'bad.json'
    path.write_text(json.dumps({**rig().as_json(), **change}))
    with pytest.raises(ParameterError, match=said) as err:
        load_rig(path)
    assert 'bad.json' in str(err.value)


def test_known_latencies_move_every_camera_but_the_reference():
    moved = rig().with_latencies({'/a': 100, '/b': 400})
    assert moved.camera('/a').offset_ns == 0 and moved.camera('/b').offset_ns == CAM['offset_ns'] + 300


def test_the_uncertainty_away_from_the_anchor_adds_the_skew_s():
    fit = CameraFit(topic='/cam', offset_ns=5_000, skew_ppm=20.0, anchor_ns=10**18, accepted=True, cost=0.1,
                    confidence=1.0, window_ns=(0, 1), uncertainty_ns=30_000.0, skew_uncertainty_ppm=4.0)
    assert fit.uncertainty_at(10**18) == 30_000.0
    assert fit.uncertainty_at(10**18 - 10 * 10**9) == pytest.approx(50_000.0)  # 4 ppm over 10 s: 40 us
    assert replace(fit, skew_uncertainty_ppm=None).uncertainty_at(0) == 30_000.0
    assert replace(fit, uncertainty_ns=None).uncertainty_at(10**18) is None
