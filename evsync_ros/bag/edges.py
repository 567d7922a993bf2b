"""Each camera's trigger edges from a bag: where its driver put them (an evt3 camera's in its events,
a dvs camera's on a ``trigger`` topic beside them, ``events.trigger_topics``), on the channel that
carries the shared pulse."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from evsync_ros.bag.events import trigger_topics
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.ros1 import Unconverted
from evsync_ros.core.triggers import Edges
from evsync_ros.errors import BagError, EvsyncError, MessageError
from msg_adapters.edges import TriggerEdges
from msg_adapters.registry import decoder_for

__all__ = ['CameraEdges', 'channels_given', 'read_edges']


@dataclass(frozen=True)
class CameraEdges:
    """A camera's edges as read: where from, every channel's count, the chosen channel's edges, and
    the messages its decoder refused (their edges are not in it)."""

    topic: str
    source: str
    counts: dict[int, int]
    channel: int | None
    edges: Edges
    undecodable: int


def channels_given(pairs: Sequence[str] | None) -> dict[str, int]:
    """--trigger-channel TOPIC=ID ... as {topic: channel}."""
    out: dict[str, int] = {}
    for item in pairs or ():
        topic, sep, value = item.partition('=')
        if not sep or not topic.startswith('/') or not value.isdigit():
            raise EvsyncError(f'--trigger-channel wants TOPIC=ID (an absolute topic, a channel number), got {item!r}')
        out[topic] = int(value)
    return out


def read_edges(bag: str | Path, cameras: Iterable[str], *, channels: Mapping[str, int]) -> dict[str, CameraEdges]:
    """Each camera's edges on its channel: ``channels``' where given, else the one channel it has edges
    on (BagError naming the camera and its channels when it has several)."""
    with BagReader(bag) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        beside = {cam: t for t, cam in trigger_topics(reader).items() if cam is not None}
        out = {}
        for cam in cameras:
            source = beside.get(cam, cam)
            found, bad = _decoded(reader, source, types[source])
            out[cam] = _on_channel(bag, cam, source, found, bad, channels.get(cam))
    return out


def _decoded(reader: BagReader, topic: str, msgtype: str) -> tuple[TriggerEdges, int]:
    decoder = decoder_for(msgtype)
    parts, bad = [], 0
    for _, _, raw in reader.messages([topic]):
        if isinstance(raw, Unconverted):
            bad += 1
            continue
        try:
            _, edges = decoder.decode_times_edges(raw)
        except MessageError:
            bad += 1
            continue
        if len(edges):
            parts.append(edges)
    return TriggerEdges.concatenate(parts), bad


def _on_channel(bag: str | Path, cam: str, source: str, found: TriggerEdges, bad: int, channel: int | None
                ) -> CameraEdges:
    ids, n = np.unique(found.channel, return_counts=True)
    counts = {int(i): int(k) for i, k in zip(ids, n)}
    if channel is None and len(counts) > 1:
        listed = ', '.join(f'{i} ({k} edges)' for i, k in counts.items())
        raise BagError(f'{bag}: {cam} has trigger edges on channels {listed}: choose the one the shared pulse '
                       f'is wired to with --trigger-channel {cam}=ID')
    channel = channel if channel is not None else next(iter(counts), None)
    chosen = found.on_channel(channel) if channel is not None else found
    return CameraEdges(cam, source, counts, channel, Edges(chosen.t, chosen.value), bad)
