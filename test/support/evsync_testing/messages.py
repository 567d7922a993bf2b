"""Serialized event messages for the tests, made with rosbags from plain field values."""

from __future__ import annotations

import numpy as np

from msg_adapters.definitions import EVENT_PACKET, event_typestore
from msg_adapters.evt3 import encode_evt3

NS = 1_000_000_000


def _time(store, t_ns: int):
    sec, nsec = divmod(int(t_ns), NS)
    return store.types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nsec)


def packet_bytes(encoding: str, payload, *, time_base: int = 0, stamp_ns: int = 1_700_000_000 * NS,
                 seq: int = 1, width: int = 640, height: int = 480, frame_id: str = 'cam',
                 is_bigendian: bool = False) -> bytes:
    store = event_typestore()
    header = store.types['std_msgs/msg/Header'](stamp=_time(store, stamp_ns), frame_id=frame_id)
    msg = store.types[EVENT_PACKET](
        header=header, height=height, width=width, seq=seq, time_base=time_base, encoding=encoding,
        is_bigendian=is_bigendian, events=np.frombuffer(bytes(payload), np.uint8).copy())
    return bytes(store.serialize_cdr(msg, EVENT_PACKET))


def array_bytes(msgtype: str, t, x=None, y=None, p=None, *, stamp_ns: int | None = None,
                frame_id: str = 'cam', width: int = 346, height: int = 260) -> bytes:
    store = event_typestore()
    t = [int(v) for v in t]
    n = len(t)
    x = range(n) if x is None else x
    y = [2 * i for i in range(n)] if y is None else y
    p = [i % 2 for i in range(n)] if p is None else p
    event = store.types[msgtype.replace('EventArray', 'Event')]
    events = [event(x=int(a), y=int(b), ts=_time(store, c), polarity=bool(d)) for a, b, c, d in zip(x, y, t, p)]
    stamp = t[0] if stamp_ns is None and t else (stamp_ns or 0)
    header = store.types['std_msgs/msg/Header'](stamp=_time(store, stamp), frame_id=frame_id)
    msg = store.types[msgtype](header=header, height=height, width=width, events=events)
    return bytes(store.serialize_cdr(msg, msgtype))


def mono_payload(dt, x, y, p) -> bytes:
    words = (np.asarray(p, np.uint64) << 63) | (np.asarray(y, np.uint64) << 48) \
        | (np.asarray(x, np.uint64) << 32) | np.asarray(dt, np.uint64)
    return words.astype('<u8').tobytes()


def libcaer_payload(ts_us, x, y, p) -> bytes:
    data = (np.asarray(x, np.uint32) << 17) | (np.asarray(y, np.uint32) << 2) | (np.asarray(p, np.uint32) << 1)
    pairs = np.stack([data, np.asarray(ts_us, np.int64).astype(np.uint32)], axis=1)
    return pairs.astype('<u4').tobytes()


def rewritten(messages: list[bytes], encoding: str) -> list[bytes]:
    """An EventPacket stream of a time_base encoding (a libcaer_cmp recording) written in another
    (libcaer, mono): the same events, time_base, seq, geometry and stamp."""
    from msg_adapters.event_packet import EventPacketDecoder
    decoder, out = EventPacketDecoder(), []
    for raw in messages:
        view, events = decoder.decode(raw, xyp=True)
        rel = events.t - view.time_base
        assert rel.size == 0 or 0 <= rel.min() <= rel.max() < 1 << 32, 'beyond what both encodings hold'
        payload = (libcaer_payload(rel // 1000, events.x, events.y, events.p) if encoding == 'libcaer'
                   else mono_payload(rel, events.x, events.y, events.p))
        out.append(packet_bytes(encoding, payload, time_base=view.time_base, seq=view.seq, stamp_ns=view.stamp_ns,
                                width=view.width, height=view.height))
    return out


def evt3_packets(n: int, *, start_us: int = 5_000, seq0: int = 0, width: int = 640, height: int = 480,
                 stamp_ns: int = 1_700_000_000 * NS) -> list[bytes]:
    """n evt3 packets of four events each, 1 ms apart, stamped at their first event's time."""
    out = []
    for i in range(n):
        t = start_us + 1000 * i + np.arange(4) * 100
        out.append(packet_bytes('evt3', encode_evt3(t, np.arange(4) * 200, np.arange(4) * 150, np.ones(4)),
                                seq=seq0 + i, width=width, height=height,
                                stamp_ns=stamp_ns + 1000 * (int(t[0]) - start_us)))
    return out


ONE_EVENT = encode_evt3(np.array([7_000]), np.array([1]), np.array([1]), np.array([1]))
"""evt3 words of one event."""


def odd_evt3_packets(good: list[bytes]) -> list[bytes]:
    """What an evt3 packet can be that the C paths leave to Python (or refuse), made from ``good``
    (two packets or more): cut, big-endian, empty, eventless, flagged big-endian, with a time_base,
    of another encoding, with an odd byte."""
    return [
        good[0][:-3],  # truncated payload
        good[1][:40],  # truncated header
        b'\x01\x00' + good[1][2:],  # big-endian CDR
        packet_bytes('evt3', b'', seq=9),  # no payload
        packet_bytes('evt3', bytes.fromhex('0080') + bytes.fromhex('0060'), seq=10),  # time words, no event
        packet_bytes('evt3', ONE_EVENT, seq=11, is_bigendian=True),
        packet_bytes('evt3', ONE_EVENT, seq=12, time_base=5 * NS),  # time_base set: another branch
        packet_bytes('evt2', ONE_EVENT, seq=13),  # no such encoding
        packet_bytes('evt3', ONE_EVENT + b'\x01', seq=14),  # an odd byte after the words
    ]
