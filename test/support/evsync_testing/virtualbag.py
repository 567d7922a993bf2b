"""A virtual rig cut from a real recording (``virtual``), written as a rosbag2 the way the drivers
send it: each camera's events as event_camera_msgs/EventPacket evt3, one packet per millisecond
(metavision_driver's and libcaer_driver's default), for the bag tools and the live node to read.

Each camera's sensor time counts microseconds from its own start (the second camera's on its own
clock: offset, skew), its low 24 bits on the wire. A packet's header.stamp is the host time its
first event arrived, 0.4 ms plus a random latency (mean 0.3 ms) after it happened (never before the
packet before's: a driver reads the sensor's buffers in order), and its record time the host time
it was recorded, 0.5 ms after its last event (not before its stamp); host time is the recording's time
moved to ``simbag.HOST_EPOCH_NS``. The truth is in the ``evsync estimate`` contract, on the
timelines the adapters decode: sensor time anchored by each camera's first header.stamp
(``sim.simbag`` notes). The second camera's event times are the ones ``virtual_rig`` gives it (split,
camera of another make, thinning, jitter, noise, hot pixels, cut, late start, early stop, gap,
offset, skew): a jittered event is stamped, and sent, at its jittered time; a noise event gets a
random pixel and polarity, a hot pixel one random pixel for all its events. A case with a clock step
is refused.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from evsync_ros.bag.writer import BagWriter
from evsync_ros.errors import BagError, ParameterError
from evsync_ros.sim.simbag import HOST_EPOCH_NS
from evsync_testing.virtual import Case, added_events, cut_index, instant_of, recorded, second_clock
from msg_adapters.definitions import EVENT_PACKET
from msg_adapters.event_packet import encode_event_packet
from msg_adapters.evt3 import encode_evt3

PACKET_NS = 1_000_000
"""The drivers' default: one packet per millisecond."""
START_US = 1_000_000
"""Each camera's sensor time at its first event (the second camera's clock may run behind it)."""
TOPICS = ('/cam0/events', '/cam1/events')


def _packets(true_ns: np.ndarray, sensor_us: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, *,
             frame_id: str, width: int, height: int, rng: np.random.Generator) -> tuple[list[tuple[int, bytes]], int]:
    """(record time, serialized EventPacket) per millisecond of sensor time, and the camera's first
    header.stamp less its first sensor time (ns): where its decoded timeline sits."""
    key = (sensor_us - sensor_us[0]) // (PACKET_NS // 1000)
    bounds = np.concatenate(([0], np.flatnonzero(np.diff(key)) + 1, [key.size])).tolist()
    out: list[tuple[int, bytes]] = []
    anchor = arrival = 0
    for seq, (i, j) in enumerate(zip(bounds[:-1], bounds[1:])):
        # a driver reads the sensor's buffers in order: its stamps never go back
        arrival = max(arrival, HOST_EPOCH_NS + int(true_ns[i]) + 400_000 + int(rng.exponential(300_000)))
        if seq == 0:
            anchor = arrival - int(sensor_us[i]) * 1000
        raw = encode_event_packet(stamp_ns=arrival, frame_id=frame_id, width=width, height=height, seq=seq + 1,
                                  time_base=0, encoding='evt3',
                                  payload=encode_evt3(sensor_us[i:j], x[i:j], y[i:j], p[i:j]))
        out.append((max(arrival, HOST_EPOCH_NS + int(true_ns[j - 1]) + 500_000), raw))
    return out, anchor


def _second_camera(case: Case, events: tuple[np.ndarray, ...], b: np.ndarray, draws: np.random.Generator, *,
                   t0: int, t1: int, width: int, height: int) -> tuple[np.ndarray, ...]:
    """(t, x, y, polarity) of the second camera's events in time order, as it recorded them: its share
    of the recording jittered, with its background noise (each event at a random pixel) and hot
    pixels (each at one random pixel), the times drawn from ``draws`` as ``virtual_rig`` draws them."""
    times, extra = added_events(case, events[0][b].astype(np.int64), draws, t0=t0, t1=t1)
    pixels = np.random.default_rng([case.seed, 13])
    xs, ys, ps = [events[1][b]], [events[2][b]], [events[3][b]]
    for i, added in enumerate(extra):
        one = not (i == 0 and case.noise)  # a hot pixel: all its events at one pixel
        n = 1 if one else added.size
        x, y, p = pixels.integers(0, width, n), pixels.integers(0, height, n), pixels.integers(0, 2, added.size)
        xs.append(np.broadcast_to(x, added.shape).astype(events[1].dtype))
        ys.append(np.broadcast_to(y, added.shape).astype(events[2].dtype))
        ps.append(p.astype(events[3].dtype))
    t = np.concatenate([times, *extra])
    order = np.argsort(t, kind='stable')
    kept = order[recorded(case, t[order], t0=t0, t1=t1)]
    return t[kept], np.concatenate(xs)[kept], np.concatenate(ys)[kept], np.concatenate(ps)[kept]


def write_bag(case: Case, events: tuple[np.ndarray, ...], bag: str | Path, *, width: int = 1280,
              height: int = 720) -> dict[str, Any]:
    """Write the virtual rig ``case`` of the recording ``events`` (t ns, x, y, polarity) to the rosbag2
    ``bag`` (sqlite3), the first camera on ``/cam0/events`` (the reference), the second on
    ``/cam1/events``; returns the truth, as ``sim.simbag.write_rig`` gives it (the contract's form,
    each camera with its ``topic`` and ``encoding``).

    Raises:
        ParameterError: the case has a clock step (``virtual_rig`` steps its clock after the events
            are drawn; not written here).
        BagError: ``bag`` exists already.
    """
    if case.step:
        raise ParameterError(f'virtual rig {case.name!r}: a clock step cannot be written as a bag')
    if Path(bag).exists():
        raise BagError(f'{bag}: exists already; refusing to overwrite it')
    t = events[0].astype(np.int64)
    draws = np.random.default_rng([case.seed, 7])
    a, b, t0, t1 = cut_index(case, events, draws)  # as virtual_rig draws
    a = a[np.argsort(t[a], kind='stable')]
    first = (t[a], events[1][a], events[2][a], events[3][a])
    second = _second_camera(case, events, b, draws, t0=t0, t1=t1, width=width, height=height)
    k = case.skew_ppm * 1e-6
    true = {TOPICS[0]: first[0] - t0, TOPICS[1]: second[0] - t0}  # ns from the rig's start
    clock_b = second_clock(case, second[0], t0=t0)  # as virtual_rig sets it
    origin_b = int(clock_b[0])
    sensor = {TOPICS[0]: (true[TOPICS[0]] - int(true[TOPICS[0]][0])) // 1000 + START_US,
              TOPICS[1]: (clock_b - origin_b) // 1000 + START_US}
    rng = np.random.default_rng([case.seed, 11])
    messages: list[tuple[int, str, bytes]] = []
    anchors = {}
    for topic, (_, x, y, pol) in zip(TOPICS, (first, second)):
        packets, anchors[topic] = _packets(true[topic], sensor[topic], x, y, pol,
                                           frame_id=topic.strip('/').split('/')[0], width=width,
                                           height=height, rng=rng)
        messages += [(stamp, topic, raw) for stamp, raw in packets]
    messages.sort(key=lambda m: m[0])
    with BagWriter(bag) as writer:
        conns = {topic: writer.add_topic(topic, EVENT_PACKET) for topic in TOPICS}
        for stamp, topic, raw in messages:
            writer.write(conns[topic], stamp, raw)
    # timelines as decoded: cam0's = anchor0 + 1000 * sensor0, sensor0 = (true - true0) / 1000 + START_US;
    # cam1's = anchor1 + 1000 * sensor1, sensor1 = (clock - origin) / 1000 + START_US (second_clock). About
    # the median of cam1's events, on its timeline:
    base0 = anchors[TOPICS[0]] + START_US * 1000 - int(true[TOPICS[0]][0])  # cam0's timeline less true
    base1 = anchors[TOPICS[1]] + START_US * 1000 - origin_b  # cam1's timeline less its clock
    mid_clock = t0 + int(np.median(clock_b - t0))  # about t0: float64 near 1e18 ns keeps 256 ns steps
    anchor = base1 + mid_clock
    offset = base0 + round(instant_of(case, mid_clock, t0=t0)) - anchor
    cams = [{'topic': TOPICS[0], 'encoding': 'evt3', 'width': width, 'height': height, 'events': int(a.size),
             'offset_ns': 0, 'skew_ppm': 0.0, 'anchor_ns': 0},
            {'topic': TOPICS[1], 'encoding': 'evt3', 'width': width, 'height': height, 'events': int(second[0].size),
             'offset_ns': int(offset), 'skew_ppm': (1 / (1 + k) - 1) * 1e6, 'anchor_ns': int(anchor)}]
    return {'reference': TOPICS[0], 'seed': case.seed, 'duration_ns': int(t[-1]) - t0, 'cameras': cams,
            'case': case.name}
