"""A bag's content as one digest: what tests of byte-for-byte outputs compare."""

from __future__ import annotations

import hashlib
from pathlib import Path

from evsync_ros.bag.reader import BagReader

__all__ = ['bag_digest']


def bag_digest(bag: str | Path) -> str:
    """sha256 of a bag's topics and of its messages in read order (topic, record time, its own bytes;
    a ROS 1 bag's as ROS 1 bytes)."""
    h = hashlib.sha256()
    with BagReader(bag) as reader:
        for conn in sorted(reader.connections, key=lambda c: c.topic):
            h.update(repr((conn.topic, conn.msgtype, conn.msgdef.data, conn.digest, conn.ext)).encode())
        for conn, timestamp, raw in reader.messages(native=True):
            h.update(f'{conn.topic} {timestamp} {len(raw)}'.encode())
            h.update(raw)
    return h.hexdigest()
