"""Copies of one real event stream, each on a clock shifted by a known offset and written in an
encoding of its own, as the drivers write them: rigs whose restamped outputs must carry equal
``header.stamp`` for equal instants (the one stamp rule, docs/messages.md).

``davis_copies``: the real DAVIS346 libcaer_cmp stream as the reference, unchanged, and three copies
of it: libcaer_cmp (its ``time_base`` shifted, its arrival stamp later by a lag of its own), evt3
(sensor time in the time words, ``header.stamp`` the message's arrival as metavision_driver stamps
it) and a dvs EventArray (``header.stamp`` the message's last event, as the Prophesee wrapper stamps
it). ``evt3_copies``: the real evt3 stream as the reference and a shifted copy that arrives with
other latencies. Each copy's correction (``Copies.corrections``) is the one that puts its events
back on the reference's timeline exactly.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.writer import BagWriter
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.results import CameraFit, RigFit
from msg_adapters.cdr import write_stamp
from msg_adapters.definitions import DVS_EVENT_ARRAY, EVENT_PACKET, event_typestore
from msg_adapters.event_array import encode_event_array
from msg_adapters.event_packet import EventPacketDecoder, encode_event_packet, parse_event_packet
from msg_adapters.evt3 import encode_evt3
from msg_adapters.registry import decoder_for

S = 1_000_000_000
MS = 1_000_000
TOPIC = '/event_camera/events'
"""The real recordings' one topic."""


@dataclass
class Copies:
    """A rig of copies of one stream: its messages in record order, and what puts each on the reference."""

    messages: list[tuple[str, int, bytes]]
    """(topic, record time ns, serialized message)."""
    types: dict[str, str]
    reference: str
    corrections: dict[str, ClockCorrection]

    def topics(self) -> list[str]:
        return list(self.types)

    def of(self, topic: str) -> list[bytes]:
        return [raw for t, _, raw in self.messages if t == topic]

    def write_bag(self, path: Path) -> Path:
        """The rig as a rosbag2 (mcap)."""
        with BagWriter(path, storage='mcap') as writer:
            conns = {topic: writer.add_topic(topic, msgtype) for topic, msgtype in self.types.items()}
            for topic, record, raw in sorted(self.messages, key=lambda m: m[1]):
                writer.write(conns[topic], record, raw)
        return path

    def write_offsets(self, path: Path) -> Path:
        """``corrections`` in the ``evsync estimate --json`` contract, every copy accepted."""
        cams = [CameraFit.reference_entry(self.reference, start_ns=0, window_ns=S)]
        cams += [CameraFit(topic=t, offset_ns=c.offset_ns, skew_ppm=c.skew_ppm, anchor_ns=c.anchor_ns, accepted=True,
                           cost=0.0, confidence=1.0, window_ns=(0, S), uncertainty_ns=0.0)
                 for t, c in self.corrections.items() if t != self.reference]
        path.write_text(json.dumps(RigFit(reference=self.reference, cameras=tuple(cams)).as_json()))
        return path


def _read(bag: Path) -> list[tuple[int, bytes]]:
    with BagReader(bag) as reader:
        return [(record, bytes(raw)) for conn, record, raw in reader.messages() if conn.topic == TOPIC]


def davis_copies(real: Path, *, seed: int = 0) -> Copies:
    """The real DAVIS346 stream (``real``: the folder of the real recordings) and three shifted copies."""
    rng = np.random.default_rng(seed)
    source = _read(real / 'libcaer_cmp_mcap')
    decoder = EventPacketDecoder()
    shift = {'/libcaer/events': 3_300_123_457, '/evt3/events': -7_250_000_000 + 987, '/dvs/events': 41_500_321}
    epoch: int | None = None
    messages: list[tuple[str, int, bytes]] = []
    for record, raw in source:
        view, ev = decoder.decode(raw, xyp=True)
        assert ev.x is not None and ev.y is not None and ev.p is not None
        messages.append(('/davis/events', record, raw))
        lag = int(rng.integers(0, 2 * MS))  # each copy's driver sees the message arrive later
        out = bytearray(raw)
        struct.pack_into('<Q', out, view.time_base_offset, view.time_base + shift['/libcaer/events'])
        write_stamp(out, view.stamp_ns + shift['/libcaer/events'] + lag, 'EventPacket')
        messages.append(('/libcaer/events', record, bytes(out)))
        if not ev.t.size:
            continue
        if epoch is None:  # the evt3 camera's sensor clock: 2 s at the first event; it arrives with no lag
            epoch = int(ev.t[0]) - 2 * S
            lag = 0
        sensor_us = (ev.t - epoch) // 1000
        messages.append(('/evt3/events', record, encode_event_packet(
            stamp_ns=int(ev.t[0]) + shift['/evt3/events'] + lag, frame_id='evt3', width=view.width,
            height=view.height, seq=view.seq, time_base=0, encoding='evt3',
            payload=encode_evt3(sensor_us, ev.x, ev.y, ev.p))))
        messages.append(('/dvs/events', record, encode_event_array(
            stamp_ns=int(ev.t[-1]) + shift['/dvs/events'], frame_id='dvs', width=view.width, height=view.height,
            t=ev.t + shift['/dvs/events'], x=ev.x, y=ev.y, p=ev.p)))
    types = {'/davis/events': EVENT_PACKET, '/libcaer/events': EVENT_PACKET, '/evt3/events': EVENT_PACKET,
             '/dvs/events': DVS_EVENT_ARRAY}
    corrections = {'/davis/events': ClockCorrection(offset_ns=0),
                   **{t: ClockCorrection(offset_ns=-d) for t, d in shift.items()}}
    return Copies(messages, types, '/davis/events', corrections)


def davis_rephased(real: Path, *, phase_ns: int, shift_ns: int = 41_500_321) -> Copies:
    """The real DAVIS346 stream and a dvs EventArray copy on a clock ``shift_ns`` later whose messages
    are cut ``phase_ns`` after the reference's (as one camera's packets fall between another's):
    pairing them on ``header.stamp`` takes a slop of up to half a packet period."""
    source = _read(real / 'libcaer_cmp_mcap')
    decoder = EventPacketDecoder()
    messages: list[tuple[str, int, bytes]] = []
    parts = []
    for record, raw in source:
        view, ev = decoder.decode(raw, xyp=True)
        messages.append(('/davis/events', record, raw))
        parts.append((record, ev))
    width, height = view.width, view.height
    t = np.concatenate([ev.t for _, ev in parts])
    xyp = [np.concatenate([getattr(ev, f) for _, ev in parts]) for f in 'xyp']
    starts = [int(ev.t[0]) + phase_ns for _, ev in parts if ev.t.size]
    cuts = np.searchsorted(t, starts + [int(t[-1]) + 1])
    for k, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
        if b > a:
            messages.append(('/dvs/events', parts[min(k + 1, len(parts) - 1)][0], encode_event_array(
                stamp_ns=int(t[b - 1]) + shift_ns, frame_id='dvs', width=width, height=height, t=t[a:b] + shift_ns,
                x=xyp[0][a:b], y=xyp[1][a:b], p=xyp[2][a:b])))
    types = {'/davis/events': EVENT_PACKET, '/dvs/events': DVS_EVENT_ARRAY}
    corrections = {'/davis/events': ClockCorrection(offset_ns=0), '/dvs/events': ClockCorrection(offset_ns=-shift_ns)}
    return Copies(messages, types, '/davis/events', corrections)


IMU = 'sensor_msgs/msg/Imu'


def with_imu(copies: Copies, *, camera: str, hz: float = 200.0, old_driver: bool = False) -> Copies:
    """``copies`` with an IMU companion of ``camera`` (``<namespace>/imu``): a sample every 1/``hz``
    over its events, each arriving with the event message it falls in. Stamped on the camera's
    event timeline, as libcaer_driver 1.5.4 stamps it; ``old_driver``: as libcaer_driver before
    1.5.4 did (libcaer_driver#12): the host time at arrival plus the sensor's time since the driver
    started (here 30 s before the first event), seconds off the events."""
    store = event_typestore()
    Imu, Header, Time = (store.types[n] for n in (IMU, 'std_msgs/msg/Header', 'builtin_interfaces/msg/Time'))
    Quaternion, Vector3 = store.types['geometry_msgs/msg/Quaternion'], store.types['geometry_msgs/msg/Vector3']
    zero, cov = Vector3(x=0.0, y=0.0, z=0.0), np.zeros(9)
    template = bytearray(store.serialize_cdr(Imu(
        header=Header(stamp=Time(sec=0, nanosec=0), frame_id='imu'),
        orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=cov, angular_velocity=zero,
        angular_velocity_covariance=cov, linear_acceleration=zero, linear_acceleration_covariance=cov), IMU))
    decoder = decoder_for(copies.types[camera])
    spans = []
    for topic, record, raw in copies.messages:
        if topic == camera:
            t = decoder.decode(raw)[1].t
            if t.size:
                spans.append((int(t[0]), int(t[-1]), record))
    start = spans[0][0] - 30 * S
    imu: list[tuple[str, int, bytes]] = []
    for first, last, record in spans:
        for u in range(first + (-first) % round(S / hz), last + 1, round(S / hz)):
            out = bytearray(template)
            write_stamp(out, record + (u - start) if old_driver else u, IMU)
            imu.append((camera.rsplit('/', 1)[0] + '/imu', record + 1, bytes(out)))
    topic = camera.rsplit('/', 1)[0] + '/imu'
    return Copies(copies.messages + imu, {**copies.types, topic: IMU}, copies.reference, copies.corrections)


def evt3_copies(real: Path, *, seed: int = 0, shift_ns: int = 2_345_678_901) -> Copies:
    """The real evt3 stream and a copy on a clock ``shift_ns`` later whose messages arrive with other
    latencies (its first with the same: the copy's decoder anchors there)."""
    rng = np.random.default_rng(seed)
    messages: list[tuple[str, int, bytes]] = []
    for k, (record, raw) in enumerate(_read(real / 'evt3_sqlite3')):
        messages.append(('/prophesee/events', record, raw))
        lag = int(rng.integers(-MS, 3 * MS)) if k else 0
        out = bytearray(raw)
        write_stamp(out, parse_event_packet(raw).stamp_ns + shift_ns + lag, 'EventPacket')
        messages.append(('/copy/events', record, bytes(out)))
    types = {'/prophesee/events': EVENT_PACKET, '/copy/events': EVENT_PACKET}
    corrections = {'/prophesee/events': ClockCorrection(offset_ns=0),
                   '/copy/events': ClockCorrection(offset_ns=-shift_ns)}
    return Copies(messages, types, '/prophesee/events', corrections)


def unequal_instants(copies: Copies, outputs: dict[str, list[bytes]]) -> list[str]:
    """What breaks the stamp rule in ``outputs`` (per topic, the restamped messages in order), decoded
    as consumers decode them, from each stream's first message and from each message on its own (a
    consumer that joins there; evt3 anchors its sensor time on that message's header.stamp): a
    copy's message whose ``header.stamp`` or event times differ from the reference's message of the
    same events, a stamp that is not the time of the first event a joining consumer decodes, or a
    joining consumer that decodes other times than one there from the start. Empty: none."""
    def decode(topic: str, raws: list[bytes]) -> list[tuple[int, np.ndarray, np.ndarray]]:
        dec = decoder_for(copies.types[topic])
        out = []
        for raw in raws:
            view, ev = dec.decode(raw)
            out.append((view.stamp_ns, ev.t, decoder_for(copies.types[topic]).decode(raw)[1].t))
        return out

    problems: list[str] = []
    ref = decode(copies.reference, outputs[copies.reference])
    for topic in copies.topics():
        got = decode(topic, outputs[topic])
        if len(got) != len(ref):
            problems.append(f'{topic}: {len(got)} messages, the reference {len(ref)}')
            continue
        for k, ((stamp, t, joined), (ref_stamp, ref_t, _)) in enumerate(zip(got, ref)):
            if not t.size:
                continue
            first = int(joined[0]) if joined.size else int(t[0])
            if stamp != ref_stamp or stamp != first:
                problems.append(f'{topic} message {k}: header.stamp {stamp - ref_stamp:+d} ns from the '
                                f"reference's, {stamp - first:+d} ns from its first event")
            if t.shape != ref_t.shape:
                problems.append(f"{topic} message {k}: {t.size} events, the reference's {ref_t.size}")
            elif not np.array_equal(t, ref_t):
                far = int(np.abs(t - ref_t).max())
                problems.append(f'{topic} message {k}: events up to {far} ns from the reference')
            if not np.array_equal(joined, t[t.size - joined.size:]):  # those before its first time word: lost
                problems.append(f'{topic} message {k}: a consumer joining there decodes other times')
    return problems
