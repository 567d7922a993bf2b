"""Bags of every origin a user has: one recording's record times rewritten as another recorder would
have written them (issue 50). Our own writers record one host's arrival times; a bag merged from two
hosts, converted from a dataset, or simulated on each camera's clock has other record times, and the
estimate must judge them before it trusts them.

* ``HOST``: unchanged (one host's arrival times).
* ``CAMERA_CLOCK``: each message recorded at its last event's time on its camera's own clock, that clock
  starting at zero at the camera's first event (the paper's setting: every camera's clock starts at
  zero when it starts), 0.5 ms later.
* ``SECOND_HOST``: every camera but the reference recorded on a second host whose clock runs
  ``SECOND_HOST_NS`` ahead: its record times, and the host times its driver writes (``header.stamp``,
  libcaer's ``time_base``, an EventArray's ``ts``), that much later; its decoded event times move with
  them, so its true offset is ``SECOND_HOST_NS`` less (``truth``).
* ``HEADER_STAMP``: each message recorded at its own ``header.stamp`` (a converter that takes the
  stamp for the record time).
"""

from __future__ import annotations

import struct
from enum import Enum
from pathlib import Path
from typing import Any

from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.writer import BagWriter
from evsync_ros.core.clock import ClockCorrection
from msg_adapters.cdr import read_stamp, write_stamp
from msg_adapters.definitions import EVENT_PACKET
from msg_adapters.event_array import restamp_event_array
from msg_adapters.event_packet import parse_event_packet
from msg_adapters.registry import decoder_for, is_event_type, normalise_type

__all__ = ['SECOND_HOST_NS', 'Origin', 'rewrite', 'truth']

SECOND_HOST_NS = 3_456_789_012
"""How far the second host's clock runs ahead of the first's (a host without NTP, seconds off)."""
CAMERA_LATENCY_NS = 500_000


class Origin(str, Enum):
    """Where a bag's record times come from."""

    HOST = 'host'
    CAMERA_CLOCK = 'camera-clock'
    SECOND_HOST = 'second-host'
    HEADER_STAMP = 'header-stamp'


def _second_host(raw: bytes, msgtype: str) -> bytes:
    """A message as the second host's driver would have written it: every host time ``SECOND_HOST_NS`` later."""
    if normalise_type(msgtype) == EVENT_PACKET:
        view = parse_event_packet(raw)
        out = bytearray(raw)
        write_stamp(out, view.stamp_ns + SECOND_HOST_NS, 'EventPacket')
        if view.encoding != 'evt3':  # evt3's times are anchored on the stamp; the others' on time_base
            struct.pack_into('<Q', out, view.time_base_offset, view.time_base + SECOND_HOST_NS)
        return bytes(out)
    stamp = read_stamp(raw)
    out = restamp_event_array(raw, ClockCorrection(offset_ns=SECOND_HOST_NS))
    write_stamp(out, stamp + SECOND_HOST_NS, msgtype)
    return bytes(out)


def rewrite(src: Path, dst: Path, origin: Origin, *, reference: str, storage: str = 'mcap') -> Path:
    """``src`` written again at ``dst`` with the record times of ``origin`` (module notes), in the order
    of the new record times, as a recorder or a merge would write them. Topics that are not events keep
    their messages; under ``CAMERA_CLOCK`` and ``HEADER_STAMP`` they are recorded at their header.stamp."""
    rows: list[tuple[int, str, bytes]] = []
    with BagReader(src) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        decoders = {t: decoder_for(m) for t, m in types.items() if is_event_type(m)}
        first: dict[str, int] = {}
        last: dict[str, int] = {}
        for conn, record, raw in reader.messages():
            raw = bytes(raw)
            topic = conn.topic
            if origin is Origin.HOST:
                rows.append((record, topic, raw))
                continue
            if origin is Origin.SECOND_HOST:
                moved = topic in decoders and topic != reference
                rows.append((record + SECOND_HOST_NS if moved else record, topic,
                             _second_host(raw, types[topic]) if moved else raw))
                continue
            if origin is Origin.HEADER_STAMP or topic not in decoders:
                rows.append((read_stamp(raw), topic, raw))
                continue
            t = decoders[topic].decode(raw)[1].t
            if t.size:
                first.setdefault(topic, int(t[0]))
                last[topic] = int(t[-1])
            rows.append((last[topic] - first[topic] + CAMERA_LATENCY_NS if topic in last else CAMERA_LATENCY_NS,
                         topic, raw))
    rows.sort(key=lambda r: r[0])
    with BagWriter(dst, storage=storage) as writer:
        conns = {t: writer.add_topic(t, m) for t, m in types.items()}
        for record, topic, raw in rows:
            writer.write(conns[topic], record, raw)
    return dst


def truth(camera: dict[str, Any], origin: Origin, *, reference: str) -> dict[str, Any]:
    """A camera's true map onto the reference (the estimate contract's entry) in a bag of ``origin``
    rewritten from one with truth ``camera``: a second host's camera's times are ``SECOND_HOST_NS``
    later, so its offset is that much less and its anchor that much later."""
    if origin is not Origin.SECOND_HOST or camera['topic'] == reference:
        return dict(camera)
    return {**camera, 'offset_ns': camera['offset_ns'] - SECOND_HOST_NS,
            'anchor_ns': camera['anchor_ns'] + SECOND_HOST_NS}


def paper_rig(path: Path, *, start_gap_ns: int = 777_000_000, duration_s: float = 22.0, preset: str = 'bursty',
              seed: int = 0) -> dict[str, Any]:
    """The paper's setting as a converter writes it: two dvs cameras of a simulator preset whose clocks
    each start at zero when the camera starts, the second ``start_gap_ns`` after the first, written with
    each message's header.stamp (its first event's time on its camera's clock) as its record time.
    Returns the truth (``sim.simbag``'s JSON)."""
    from dataclasses import replace

    from evsync_ros.sim import pixelsim, simbag

    rig = pixelsim.preset(preset, seed=seed, duration_s=duration_s)
    first, second = rig.cameras[:2]
    start = first.start_ns
    rig = replace(rig, cameras=(replace(first, encoding='dvs', start_ns=start, clock_at_start_ns=0, skew_ppm=0.0),
                                replace(second, encoding='dvs', start_ns=start + start_gap_ns, clock_at_start_ns=0,
                                        skew_ppm=0.0)))
    host = path.with_name(path.name + '.host')
    found = simbag.write_rig(rig, pixelsim.simulate(rig), host, truth=path.with_name(path.name + '.truth.json'))
    rewrite(host, path, Origin.HEADER_STAMP, reference=rig.reference)
    import shutil
    shutil.rmtree(host)
    return found


def merged_copies(real: Path, name: str, dst: Path, *, shift_ns: int, hosts: bool = True) -> Path:
    """Two copies of the real recording ``name`` (a folder of ``real``) as one bag: ``/a/events`` as
    recorded, ``/b/events`` on a second host whose clock runs ``shift_ns`` ahead (its header stamps, its
    libcaer ``time_base`` and, with ``hosts``, its record times that much later: a bag merged from two
    hosts' recordings; without ``hosts``, recorded by the first host). Its true offset is -``shift_ns``."""
    rows: list[tuple[int, str, bytes]] = []
    with BagReader(real / name) as reader:
        for _, record, raw in reader.messages():
            rows.append((record, '/a/events', bytes(raw)))
            view = parse_event_packet(raw)
            out = bytearray(raw)
            write_stamp(out, view.stamp_ns + shift_ns, 'EventPacket')
            if view.encoding != 'evt3':
                struct.pack_into('<Q', out, view.time_base_offset, view.time_base + shift_ns)
            rows.append((record + (shift_ns if hosts else 0), '/b/events', bytes(out)))
    rows.sort(key=lambda r: r[0])
    with BagWriter(dst, storage='mcap') as writer:
        conns = {t: writer.add_topic(t, EVENT_PACKET) for t in ('/a/events', '/b/events')}
        for record, topic, raw in rows:
            writer.write(conns[topic], record, raw)
    return dst
