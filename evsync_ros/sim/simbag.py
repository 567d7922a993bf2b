"""A simulated rig written as a rosbag2, with its ground truth as JSON.

Each camera's events (from ``pixelsim``) become messages of its encoding:

* ``evt3``: event_camera_msgs/EventPacket, as metavision_driver sends it. Sensor time is the
  camera's clock in microseconds (its low 24 bits on the wire), time_base 0, and header.stamp the
  host time at which the message's first event arrived (0.4 ms plus a random latency).
  Messages of ``EVT3_MESSAGE_NS``.
* ``dvs``: dvs_msgs/EventArray; every event's ts is the camera's clock, header.stamp the
  first event's. Messages of ``DVS_MESSAGE_NS``.

The bag's record timestamps are host times of arrival. Host time is true time plus ``HOST_EPOCH_NS``;
each camera's map onto it is in the truth JSON too (``host``), for ``--reference host``.

With a trigger train (``Rig.triggers``), each camera's recorded edges go where its kind of driver
would send them: an evt3 camera's as EXT_TRIGGER words among its events, in time order (sensor
time, as the events); a dvs camera's, as no DAVIS driver sends any (docs/messages.md), as
EventPackets of the ``trigger`` encoding on ``<namespace>/trigger``, one per edge, ``time_base`` its
stamp on the camera's clock. The truth JSON gives the train and each camera's record of it.

With IMU samples (``simulate(rig, imu_hz=...)``), each camera also gets ``<namespace>/imu``
(sensor_msgs/Imu, no orientation: covariance[0] -1), stamped on the camera's own timeline as
libcaer_driver stamps a DAVIS's IMU: the clock its events are decoded on.

**Ground truth.** A camera's timeline is what ``msg_adapters`` decodes: the clock for dvs, and for
evt3 the sensor time anchored by the first message's header.stamp (see ``event_packet``), so
timeline(t) = D + clock(t) with D = 0 for dvs and D = stamp_0 - sensor_0 for evt3. Between two
cameras the map is exactly linear; the JSON gives it in the ``evsync estimate`` contract:
reference time = t + offset_ns + skew_ppm * 1e-6 * (t - anchor_ns), t on the camera's timeline.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from evsync_ros.bag.writer import BagWriter
from evsync_ros.errors import BagError
from evsync_ros.sim.pixelsim import (
    ACCEL_NOISE,
    GYRO_NOISE,
    NS,
    CameraEvents,
    PixelCamera,
    Rig,
    camera_clock,
    skew_against,
)
from evsync_ros.sim.triggers import train_edges
from msg_adapters.definitions import DVS_EVENT_ARRAY, EVENT_PACKET, event_typestore
from msg_adapters.event_array import encode_event_array
from msg_adapters.event_packet import encode_event_packet
from msg_adapters.evt3 import encode_evt3
from msg_adapters.trigger import encode_trigger

HOST_EPOCH_NS = 1_763_700_000 * 1_000_000_000
EVT3_MESSAGE_NS = 5_000_000
DVS_MESSAGE_NS = 10_000_000


def _groups(t: np.ndarray, span_ns: int) -> list[tuple[int, int]]:
    if t.size == 0:
        return []
    key = (t - t[0]) // span_ns
    cuts = np.flatnonzero(np.diff(key)) + 1
    bounds = np.concatenate([[0], cuts, [t.size]])
    return list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))


def _edge_groups(ev: CameraEvents, groups: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """Which of an evt3 camera's recorded trigger edges go into each message of ``groups``: those of
    its time span, those after it until the next message (where no event made one), those before
    the first in the first; so that the messages, their stamps and D are what they are without
    triggers."""
    if ev.triggers is None or not groups:
        return [(0, 0)] * len(groups)
    starts = ev.t[[a for a, _ in groups]]
    cut = np.searchsorted(ev.triggers.t, starts[1:], side='left')
    bounds = np.concatenate([[0], cut, [ev.triggers.t.size]])
    return list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))


def _messages(ev: CameraEvents, rng: np.random.Generator) -> tuple[list[tuple[int, bytes]], int]:
    """(record timestamp, serialized message) pairs, and D (timeline minus clock)."""
    cam = ev.camera
    out = []
    offset_d = 0
    frame_id = cam.topic.strip('/').split('/')[0]
    if cam.encoding == 'evt3':
        sensor_us = ev.t // 1000
        groups = _groups(ev.t, EVT3_MESSAGE_NS)
        for seq, ((a, b), (c, d)) in enumerate(zip(groups, _edge_groups(ev, groups))):
            arrival = HOST_EPOCH_NS + int(ev.true_t[a]) + 400_000 + int(rng.exponential(300_000))
            edges = None
            last_true = ev.true_t[b - 1]
            if d > c:
                assert ev.triggers is not None  # edges only where there are some
                tr = ev.triggers
                edges = (tr.t[c:d] // 1000, tr.value[c:d], np.full(d - c, tr.channel))
                last_true = max(last_true, float(tr.true_t[d - 1]))
            raw = encode_event_packet(
                stamp_ns=arrival, frame_id=frame_id, width=cam.width, height=cam.height,
                seq=seq + 1, time_base=0, encoding='evt3',
                payload=encode_evt3(sensor_us[a:b], ev.x[a:b], ev.y[a:b], ev.p[a:b], edges=edges))
            if seq == 0:
                offset_d = arrival - int(sensor_us[0]) * 1000
            out.append((HOST_EPOCH_NS + int(last_true) + 500_000, raw))
    else:
        for a, b in _groups(ev.t, DVS_MESSAGE_NS):
            raw = encode_event_array(stamp_ns=int(ev.t[a]), frame_id=frame_id,
                                     width=cam.width, height=cam.height, t=ev.t[a:b], x=ev.x[a:b], y=ev.y[a:b],
                                     p=ev.p[a:b])
            out.append((HOST_EPOCH_NS + int(ev.true_t[b - 1]) + 500_000, raw))
    return out, offset_d


def imu_topic(event_topic: str) -> str:
    """The IMU topic beside a camera's event topic: /cam0/events -> /cam0/imu."""
    head, _, _ = event_topic.rstrip('/').rpartition('/')
    return f'{head}/imu'


def trigger_topic(cam: PixelCamera) -> str:
    """Where a camera's trigger edges are: an evt3 camera's in its event stream, a dvs camera's on
    the ``trigger`` topic beside it (/cam1/events -> /cam1/trigger)."""
    if cam.encoding == 'evt3':
        return cam.topic
    head, _, _ = cam.topic.rstrip('/').rpartition('/')
    return f'{head}/trigger'


def _trigger_messages(ev: CameraEvents, rng: np.random.Generator) -> list[tuple[int, bytes]]:
    """(record timestamp, serialized EventPacket ``trigger``) of a dvs camera's edges, one message
    per edge: time_base its stamp on the camera's clock (its events' timeline), dt 0, header.stamp
    its arrival on the host (0.4 ms plus a random latency), geometry 1x1 (as metavision_ros_driver
    sent trigger messages)."""
    tr = ev.triggers
    assert tr is not None
    frame_id = ev.camera.topic.strip('/').split('/')[0]
    out = []
    for seq, (t, true_t, value) in enumerate(zip(tr.t.tolist(), tr.true_t.tolist(), tr.value.tolist())):
        arrival = HOST_EPOCH_NS + true_t + 400_000 + int(rng.exponential(300_000))
        out.append((arrival, encode_event_packet(stamp_ns=arrival, frame_id=frame_id, width=1, height=1, seq=seq + 1,
                                                 time_base=t, encoding='trigger',
                                                 payload=encode_trigger([0], [value], [tr.channel]))))
    return out


def trigger_truth(rig: Rig, events: Mapping[str, CameraEvents], offsets_d: Mapping[str, int]
                  ) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """The truth JSON's ``triggers`` (the train: its settings, its edges' true times and values) and
    each camera's (where its edges are, which edges of the train it recorded and which it missed, and
    their true times on its timeline: D + its clock at the edge's true time, no jitter)."""
    train = rig.triggers
    assert train is not None
    true_ns, value = train_edges(train, rig.scene.duration_ns)
    top = {'hz': train.hz, 'duty': train.duty, 'phase_ns': train.phase_ns, 'jitter_ns': train.jitter_ns,
           'miss_rate': train.miss_rate, 'channel': train.channel, 'true_ns': true_ns.tolist(),
           'value': value.tolist()}
    per_camera = {}
    for cam in rig.cameras:
        tr = events[cam.topic].triggers
        assert tr is not None
        on_timeline = offsets_d[cam.topic] + camera_clock(cam, true_ns[tr.index])
        encoding = 'evt3' if cam.encoding == 'evt3' else 'trigger'
        per_camera[cam.topic] = {'topic': trigger_topic(cam), 'encoding': encoding,
                                 'channel': tr.channel, 'index': tr.index.tolist(),
                                 'times_ns': on_timeline.tolist(), 'missed': tr.missed.tolist()}
    return top, per_camera


def _imu_messages(ev: CameraEvents, offset_d: int) -> list[tuple[int, bytes]]:
    """(record timestamp, serialized sensor_msgs/Imu) of a camera's IMU, on its events' timeline."""
    imu = ev.imu
    assert imu is not None
    store = event_typestore()
    Imu, Header, Time = (store.types[n] for n in ('sensor_msgs/msg/Imu', 'std_msgs/msg/Header',
                                                   'builtin_interfaces/msg/Time'))
    Quaternion, Vector3 = store.types['geometry_msgs/msg/Quaternion'], store.types['geometry_msgs/msg/Vector3']
    frame_id = ev.camera.topic.strip('/').split('/')[0] + '_imu'
    no_orientation = np.zeros(9)
    no_orientation[0] = -1.0
    gyro_cov = np.eye(3).ravel() * GYRO_NOISE ** 2
    accel_cov = np.eye(3).ravel() * ACCEL_NOISE ** 2
    out = []
    for t, true_t, g, a in zip((imu.t + offset_d).tolist(), imu.true_t.tolist(), imu.gyro, imu.accel):
        msg = Imu(header=Header(stamp=Time(sec=t // NS, nanosec=t % NS), frame_id=frame_id),
                  orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=no_orientation,
                  angular_velocity=Vector3(x=float(g[0]), y=float(g[1]), z=float(g[2])),
                  angular_velocity_covariance=gyro_cov,
                  linear_acceleration=Vector3(x=float(a[0]), y=float(a[1]), z=float(a[2])),
                  linear_acceleration_covariance=accel_cov)
        out.append((HOST_EPOCH_NS + int(true_t) + 300_000, bytes(store.serialize_cdr(msg, 'sensor_msgs/msg/Imu'))))
    return out


def ground_truth(rig: Rig, offsets_d: dict[str, int], counts: dict[str, int]) -> dict[str, Any]:
    """Each camera's map onto the reference timeline, in the estimate contract (module notes)."""
    ref = rig.camera(rig.reference)
    k_ref = 1 + ref.skew_ppm * 1e-6
    cams = []
    for cam in rig.cameras:
        anchor = offsets_d[cam.topic] + cam.clock_at_start_ns
        at_start_on_ref = offsets_d[ref.topic] + ref.clock_at_start_ns + round(k_ref * (cam.start_ns - ref.start_ns))
        cams.append({
            'topic': cam.topic, 'encoding': cam.encoding, 'width': cam.width, 'height': cam.height,
            'contrast': cam.contrast, 'lowpass_ns': cam.lowpass_ns, 'refractory_ns': cam.refractory_ns,
            'events': counts[cam.topic],
            'offset_ns': int(at_start_on_ref - anchor) if cam.topic != ref.topic else 0,
            'skew_ppm': skew_against(ref, cam) if cam.topic != ref.topic else 0.0,
            'anchor_ns': int(anchor) if cam.topic != ref.topic else 0,
        })
    return {'reference': rig.reference, 'seed': rig.seed, 'duration_ns': rig.scene.duration_ns,
            'speed_dps': rig.scene.speed_dps, 'cameras': cams}


def write_rig(rig: Rig, events: dict[str, CameraEvents], bag: str | Path, *, storage: str = 'sqlite3',
              truth: str | Path | None = None) -> dict[str, Any]:
    """Write the bag and (beside it unless named) ``<bag>.truth.json``; returns the truth."""
    bag = Path(bag)
    truth_path = Path(truth) if truth else bag.with_name(bag.name + '.truth.json')
    if truth_path.exists():
        raise BagError(f'{truth_path}: exists already; refusing to overwrite it')
    rng = np.random.default_rng([rig.seed, 3])
    trigger_rng = np.random.default_rng([rig.seed, 5])  # apart: the event messages are the same with triggers
    offsets_d = {}
    with BagWriter(bag, storage=storage) as writer:
        streams = []
        for cam in rig.cameras:
            conn = writer.add_topic(cam.topic, EVENT_PACKET if cam.encoding == 'evt3' else DVS_EVENT_ARRAY)
            msgs, offsets_d[cam.topic] = _messages(events[cam.topic], rng)
            streams += [(stamp, i, conn, raw) for i, (stamp, raw) in enumerate(msgs)]
            if events[cam.topic].imu is not None:
                imu_conn = writer.add_topic(imu_topic(cam.topic), 'sensor_msgs/msg/Imu')
                imu_msgs = _imu_messages(events[cam.topic], offsets_d[cam.topic])
                streams += [(stamp, len(msgs) + i, imu_conn, raw) for i, (stamp, raw) in enumerate(imu_msgs)]
            if events[cam.topic].triggers is not None and cam.encoding != 'evt3':
                trigger_conn = writer.add_topic(trigger_topic(cam), EVENT_PACKET)
                streams += [(stamp, i, trigger_conn, raw)
                            for i, (stamp, raw) in enumerate(_trigger_messages(events[cam.topic], trigger_rng))]
        streams.sort(key=lambda s: (s[0], s[1]))
        for stamp, _, conn, raw in streams:
            writer.write(conn, stamp, raw)
    result = ground_truth(rig, offsets_d, {k: int(v.t.size) for k, v in events.items()})
    for cam in result['cameras']:
        if events[cam['topic']].imu is not None:
            cam['imu_topic'] = imu_topic(cam['topic'])
        cam['host'] = host_truth(rig.camera(cam['topic']), offsets_d[cam['topic']])
    if rig.triggers is not None:
        result['triggers'], per_camera = trigger_truth(rig, events, offsets_d)
        for cam in result['cameras']:
            cam['triggers'] = per_camera[cam['topic']]
    tmp = truth_path.with_name('.' + truth_path.name + '.partial')
    tmp.write_text(json.dumps(result, indent=2) + '\n')
    tmp.rename(truth_path)
    return result


def host_truth(cam: PixelCamera, offset_d: int) -> dict[str, Any]:
    """The camera's timeline onto host time (true time + ``HOST_EPOCH_NS``), in the contract's form:
    at its timeline's start (D + clock at start) it is the host time of its start, and the host
    clock runs 1 / (1 + skew) as fast as the camera's."""
    anchor = offset_d + cam.clock_at_start_ns
    return {'offset_ns': HOST_EPOCH_NS + cam.start_ns - anchor, 'skew_ppm': (1 / (1 + cam.skew_ppm * 1e-6) - 1) * 1e6,
            'anchor_ns': anchor}


def error_ns(estimate: Mapping[str, Any], truth: Mapping[str, Any], t_ns: int) -> int:
    """How far an estimate (contract form) puts camera time ``t_ns`` from where the truth puts it."""
    def mapped(c: Mapping[str, Any]) -> float:
        return t_ns + c['offset_ns'] + c['skew_ppm'] * 1e-6 * (t_ns - c['anchor_ns'])
    return int(round(mapped(estimate) - mapped(truth)))
