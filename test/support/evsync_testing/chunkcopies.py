"""A bag to restamp a chunk at a time and message by message, and the comparison of the two
(``restamp._copy_chunks`` against ``restamp._copy_messages``): real evt3 packets and real DVS128
EventArrays in the same seconds (some at the very record times of packets), a topic that is no
camera's, and malformed messages among them, in mcap or in a ROS 1 bag; with the same messages at
record times just short of the end of the bag's range, for corrections that move them out of it."""

from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import pytest
from rosbags.interfaces import ConnectionExtRosbag2
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

from evsync_ros.bag import restamp, ros1
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.restamp import LATCHED, ROS1_TIME_END, RestampReport, restamp_bag
from evsync_ros.bag.storage import Storage
from evsync_ros.bag.writer import BagWriter
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.errors import BagError
from evsync_testing.digest import bag_digest
from msg_adapters.definitions import DVS_EVENT_ARRAY, EVENT_PACKET

__all__ = ['ARRAYS', 'CASES', 'EVT3', 'OTHER', 'both_ways', 'mixed_rows', 'same_both_ways', 'write_mixed']

EVT3, ARRAYS, OTHER = '/cam0/events', '/cam1/events', '/cam1/status'
TYPES = {EVT3: EVENT_PACKET, ARRAYS: DVS_EVENT_ARRAY, OTHER: 'std_msgs/msg/String'}
STATUS = struct.pack('<4sI', b'\x00\x01\x00\x00', 7) + b'status\x00'
"""A std_msgs/String in CDR."""

CASES: dict[str, dict[str, Any]] = {
    'offset, record times moved': dict(corrections={ARRAYS: ClockCorrection(offset_ns=37_400_000)},
                                       record_time='shift'),
    'skew rewrites evt3 time words': dict(corrections={EVT3: ClockCorrection(
        offset_ns=-2_000_000, skew_ppm=80.0, anchor_ns=1_700_000_000_000_000_000)}, reference=ARRAYS,
        record_time='shift'),
    'past the re-anchoring limit, record times kept': dict(corrections={ARRAYS: ClockCorrection(
        offset_ns=3_000_000_000)}, record_time='keep'),
    'record times moved out of range': dict(corrections={ARRAYS: ClockCorrection(offset_ns=10**9)},
                                            record_time='shift'),
}
"""restamp_bag's arguments, per case (the reference EVT3 unless given); the last is for the late bag."""

Fault = Callable[[bytes], bytes]


def _messages(bag: Path, topic: str) -> list[tuple[int, bytes]]:
    with BagReader(bag) as reader:
        return [(t, bytes(raw)) for _, t, raw in reader.messages([topic])]


def mixed_rows(real_data: Path) -> list[tuple[int, str, bytes, Fault | None]]:
    """(record time, topic, CDR, fault) in record time order: a fault cuts or garbles a message once it
    is in its bag's encoding (every 50th packet cut in half, one packet's encoding named evt9, one
    EventArray cut short)."""
    evt3 = _messages(real_data / 'evt3_sqlite3', '/event_camera/events')
    arrays = _messages(real_data / 'dvs128_stereo/fan', '/left/events')[:400]
    t0 = evt3[0][0]
    moved = [(t0 + (t - arrays[0][0]) % (evt3[-1][0] - t0), raw) for t, raw in arrays]
    moved[::7] = [(evt3[i * 3][0], raw) for i, (_, raw) in enumerate(moved[::7])]  # ties across topics

    def halved(raw: bytes) -> bytes:
        return raw[: len(raw) // 2]

    def unknown(raw: bytes) -> bytes:
        return raw.replace(b'evt3', b'evt9', 1)

    def cut(raw: bytes) -> bytes:
        return raw[:-40]

    rows = [(t, EVT3, raw, halved if i % 50 == 7 else unknown if i == 11 else None) for i, (t, raw) in enumerate(evt3)]
    rows += [(t, ARRAYS, raw, cut if i == 5 else None) for i, (t, raw) in enumerate(moved)]
    rows += [(t + 1, OTHER, STATUS, None) for t, _ in evt3[::25]]
    return sorted(rows, key=lambda r: r[0])


def write_mixed(bag: Path, rows: list[tuple[int, str, bytes, Fault | None]], *, late: bool = False,
                storage: str = 'mcap') -> Path:
    """The rows as a bag (a ROS 1 bag when ``bag`` ends in .bag, else ``storage``), each fault applied
    to its message's bytes; ``late``: their record times moved to end half a second short of the
    end of the bag's range (int64's, or a ROS 1 bag's uint32 seconds'; not the recorder's clock).
    Every other evt3 packet goes through a second connection of its topic (latched in ROS 1, other
    QoS in a rosbag2), as a second publisher's would: one stream, two ids in the file."""
    storage = Storage.ROS1 if ros1.is_ros1(bag) else storage
    end = ROS1_TIME_END if storage == Storage.ROS1 else 1 << 63
    shift = end - 1 - 500_000_000 - rows[-1][0] if late else 0
    with BagWriter(bag, storage=storage) as writer:
        conns = {topic: writer.add_topic(topic, msgtype) for topic, msgtype in TYPES.items()}
        second = writer.add_topic(EVT3, TYPES[EVT3], **({'latching': True} if storage == Storage.ROS1 else
                                                        {'offered_qos_profiles': [LATCHED]}))
        packets = 0
        for t, topic, raw, fault in rows:
            packets += topic == EVT3
            conn = second if topic == EVT3 and packets % 2 else conns[topic]
            if storage == Storage.ROS1:
                own = ros1.to_ros1(writer.typestore, raw, TYPES[topic])
                writer.write_ros1(conn, t + shift, fault(own) if fault else own)
            else:
                writer.write(conn, t + shift, fault(raw) if fault else raw)
    return bag


def both_ways(src: Path, out: Path, monkeypatch: pytest.MonkeyPatch, **kwargs: Any
              ) -> tuple[RestampReport, RestampReport, Path, Path]:
    """(report, report, output, output) of restamp_bag a chunk at a time, then message by message
    (its chunk path checked taken, then turned off), into ``out``; an output of the input's kind."""
    taken = []
    chunked = restamp._copy_chunks

    def spy(*args: Any, **kw: Any) -> None:
        taken.append(True)
        chunked(*args, **kw)

    suffix = ros1.SUFFIX if ros1.is_ros1(src) else ''
    monkeypatch.setattr(restamp, '_copy_chunks', spy)
    fast = restamp_bag(src, out / f'chunks{suffix}', **kwargs)
    assert taken, 'the chunk path was not taken'
    monkeypatch.setattr(restamp, '_chunked', lambda *a, **k: None)
    slow = restamp_bag(src, out / f'messages{suffix}', **kwargs)
    return fast, slow, out / f'chunks{suffix}', out / f'messages{suffix}'


def same_both_ways(src: Path, out: Path, monkeypatch: pytest.MonkeyPatch, *, chunked: bool | None = None,
                   **kwargs: Any) -> RestampReport | str:
    """restamp_bag a chunk at a time (where the chunk path takes the bag) and message by message give
    the same: the same report and messages, or a BagError each (its class name returned). With
    ``chunked``, whether the chunk path must take the bag."""
    taken: list[bool] = []
    copy = restamp._copy_chunks

    def spy(*args: Any, **kw: Any) -> None:
        taken.append(True)
        copy(*args, **kw)

    suffix = ros1.SUFFIX if ros1.is_ros1(src) else ''
    outcomes: list[RestampReport | str] = []
    for way in ('chunks', 'messages'):
        with monkeypatch.context() as m:
            m.setattr(restamp, '_copy_chunks', spy)
            if way == 'messages':
                m.setattr(restamp, '_chunked', lambda *a, **k: None)
            try:
                outcomes.append(restamp_bag(src, out / f'{way}{suffix}', **kwargs))
            except BagError:
                outcomes.append('BagError')
        if way == 'chunks' and chunked is not None:
            assert bool(taken) == chunked, f'chunk path taken: {bool(taken)}'
    fast, slow = outcomes
    if isinstance(fast, str) or isinstance(slow, str):
        assert fast == slow
        return fast
    assert fast.topics == slow.topics
    assert bag_digest(out / f'chunks{suffix}') == bag_digest(out / f'messages{suffix}')
    return fast


def file_compressed(src: Path, dst: Path, storage: str) -> Path:
    """``src`` written again by rosbags as a bag of ``storage`` files compressed file by file (zstd),
    which rosbags decompresses whole, into a temporary directory, as it opens it."""
    with Reader(src) as reader:
        writer = Writer(dst, version=8, storage_plugin=StoragePlugin.SQLITE3 if storage == 'sqlite3'
                        else StoragePlugin.MCAP)
        writer.set_compression(CompressionMode.FILE, CompressionFormat.ZSTD)
        with writer:
            ext = {c.id: cast('ConnectionExtRosbag2', c.ext) for c in reader.connections}
            conns = {c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, rihs01=c.digest,
                                                 serialization_format=ext[c.id].serialization_format,
                                                 offered_qos_profiles=ext[c.id].offered_qos_profiles)
                     for c in reader.connections}
            for conn, stamp, raw in reader.messages():
                writer.write(conns[conn.id], stamp, raw)
    return dst
