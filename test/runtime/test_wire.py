"""What a camera process and evsync_node send each other goes through one typed wire: corrections
and reports come back as they went, and anything else is refused by name, never half-read."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine import State
from evsync_ros.core.errors import StreamError
from evsync_ros.runtime.wire import (
    CameraCorrection,
    CameraReport,
    CompanionCounters,
    PathCounters,
    decode_corrections,
    decode_report,
    encode_corrections,
    encode_report,
)


def test_corrections_come_back_as_they_went():
    sent = {'/cam0/events': CameraCorrection(State.LOCKED, 0, ClockCorrection(offset_ns=0)),
            '/cam1/events': CameraCorrection(State.LOCKED, 12_000_000,
                                             ClockCorrection(offset_ns=-1_234_567_891, skew_ppm=12.5, anchor_ns=7)),
            '/cam2/events': CameraCorrection(State.ESTIMATING, None, None)}
    assert decode_corrections(encode_corrections(sent), source='test') == sent


def test_a_report_comes_back_as_it_went_unknown_latencies_too():
    report = CameraReport('/cam1/events',
                          PathCounters(received=10, published=9, held=1, last_error='message 3: short',
                                       last_time_ns=123, messages_lost=2, publishers=1, subscribers=None),
                          {'/cam1/imu': CompanionCounters(received=4, offset_ns=-5, stamps_said='off by 2 s',
                                                          publishers=0, subscribers=2)})
    back = decode_report(encode_report(report), source='test')
    assert math.isnan(back.path.latency_p50_us) and math.isnan(back.path.latency_p99_us)  # none yet
    # NaN equals nothing, itself included
    assert (replace(back.path, latency_p50_us=0.0, latency_p99_us=0.0)
            == replace(report.path, latency_p50_us=0.0, latency_p99_us=0.0))
    assert (back.topic, back.companions) == (report.topic, report.companions)
    measured = CameraReport('/a', PathCounters(latency_p50_us=12.5, latency_p99_us=80.0), {})
    assert decode_report(encode_report(measured), source='test') == measured


@pytest.mark.parametrize(('text', 'said'), [
    ('{not json', 'not evsync corrections'),
    ('{"version": 2, "cameras": {}}', 'version 2, expected 1'),
    ('[1, 2]', 'version None'),
    ('{"version": 1}', "KeyError\\('cameras'\\)"),
    ('{"version": 1, "cameras": {"/a": {"state": "sleeping", "prior_ns": null, "correction": null}}}', 'sleeping'),
    ('{"version": 1, "cameras": {"/a": {"state": "locked", "prior_ns": 1.5, "correction": null}}}', '1.5'),
    ('{"version": 1, "cameras": {"/a": {"state": "locked", "prior_ns": 1, "correction": {"offset_ns": 1}}}}',
     'skew_ppm'),
])
def test_what_is_not_corrections_is_refused_naming_its_source(text, said):
    with pytest.raises(StreamError, match=f'the estimator: .*{said}'):
        decode_corrections(text, source='the estimator')


def test_what_is_not_a_report_is_refused_naming_its_source():
    good = json.loads(encode_report(CameraReport('/a', PathCounters(), {})))
    changes: list[dict] = [{'version': 0}, {'path': {**good['path'], 'received': '10'}},
                           {'path': {k: v for k, v in good['path'].items() if k != 'held'}},
                           {'path': {**good['path'], 'publishers': True}}, {'companions': {'/x': {}}}]
    for change in changes:
        with pytest.raises(StreamError, match='camera 2'):
            decode_report(json.dumps({**good, **change}), source='camera 2')
