"""The estimate's read of a bag: each event topic's messages decoded into event times, in bag order, with
what reading met (``TopicReport``), read in this process or ahead in a forked one while this one bins
and fits them (``BagReader.deliver``): each batch of messages' event times handed over in shared
memory, with what the engine and the report need of each message (docs/bags.md, "The estimate's
read"). The engine is fed the same times, record times and models in the same order either way."""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from evsync_ros.bag import pipeline
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.ros1 import Unconverted, adapters_convert
from evsync_ros.bag.storage import Storage
from evsync_ros.core.host import HostEnvelope
from evsync_ros.errors import BagError, MessageError
from msg_adapters.cdr import read_stamp
from msg_adapters.definitions import EVENT_PACKET
from msg_adapters.event_packet import parse_event_packet
from msg_adapters.registry import camera_model, decoder_for, is_event_type, normalise_type

__all__ = ['BATCH_MESSAGES', 'Bounded', 'Message', 'Recorder', 'TopicReport', 'batches', 'camera_topics', 'decoded',
           'event_topics', 'read_ahead', 'trigger_topics', 'unpack']

BATCH_MESSAGES = 1024
"""Messages a batch holds at most (and at most ``pipeline.SLOT_BYTES`` of event times)."""

Message = tuple[str, np.ndarray, int]
"""(topic, event times, record time) of a decoded message, as ``decoded`` yields it."""
Bounded = tuple[str, np.ndarray, int, int, int]
"""A ``Message`` with its least and greatest event time, as ``unpack`` gives it."""


@dataclass
class TopicReport:
    """What reading one event topic met: messages, events, undecodable messages (with the first
    error) and the anomalies its decoder counted."""

    msgtype: str
    messages: int = 0
    events: int = 0
    undecodable: int = 0
    first_error: str = ''
    anomalies: dict[str, int] = field(default_factory=dict)
    model: str = ''
    """What tells camera models apart in the messages: type, encoding and geometry of the first one."""


def event_topics(reader: BagReader, bag: str | Path, topics: Sequence[str] | None) -> dict[str, str]:
    """{topic: msgtype} of the event topics to use: ``topics``, checked, or every camera's event topic
    (``camera_topics``: not a topic of trigger edges)."""
    conns = {c.topic: c.msgtype for c in reader.connections}
    if topics:
        unknown = [t for t in topics if t not in conns]
        if unknown:
            raise BagError(f'{bag}: no topic {", ".join(unknown)} (topics: {", ".join(sorted(conns))})')
        wrong = [t for t in topics if not is_event_type(conns[t])]
        if wrong:
            raise BagError(f'{bag}: {", ".join(f"{t} ({conns[t]})" for t in wrong)} not an event message type')
        edges = sorted(set(topics) & set(trigger_topics(reader)))
        if edges:
            raise BagError(f'{bag}: {", ".join(edges)} carries trigger edges (EventPacket encoding trigger), not '
                           'events: it is restamped with its camera, not estimated')
        return {t: conns[t] for t in topics}
    chosen = {t: conns[t] for t in camera_topics(reader)}
    if not chosen:
        raise BagError(f'{bag}: no event topics (topics: {", ".join(sorted(conns)) or "none"})')
    return chosen


def trigger_topics(reader: BagReader) -> dict[str, str | None]:
    """{topic: its camera's event topic, or None} of the EventPacket topics that carry a camera's
    trigger edges (their first message's encoding is ``trigger``: a driver's trigger-in beside the
    events, docs/messages.md "Trigger edges"). Their camera: the one other event topic in the same
    namespace (/cam/trigger beside /cam/events), None where there is none or more than one."""
    packets = [c.topic for c in reader.connections if normalise_type(c.msgtype) == EVENT_PACKET]
    found = [t for t in packets if _first_encoding(reader, t) == 'trigger']
    if not found:
        return {}
    events = [c.topic for c in reader.connections if is_event_type(c.msgtype) and c.topic not in found]
    out: dict[str, str | None] = {}
    for topic in found:
        beside = [t for t in events if t.rpartition('/')[0] == topic.rpartition('/')[0]]
        out[topic] = beside[0] if len(beside) == 1 else None
    return out


def camera_topics(reader: BagReader) -> list[str]:
    """The bag's event topics that carry a camera's events (``trigger_topics`` left out), sorted."""
    edges = trigger_topics(reader)
    return sorted({c.topic for c in reader.connections if is_event_type(c.msgtype) and c.topic not in edges})


def _first_encoding(reader: BagReader, topic: str) -> str | None:
    """The encoding of ``topic``'s first well-formed EventPacket (None: it has none)."""
    for _, _, raw in reader.messages([topic]):
        if isinstance(raw, Unconverted):
            continue
        try:
            return parse_event_packet(raw).encoding
        except MessageError:
            continue
    return None


def decoded(reader: BagReader, chosen: Mapping[str, str], reports: dict[str, TopicReport],
            progress: Callable[[int], None] | None = None, envelope: HostEnvelope | None = None,
            window: tuple[int, int] | None = None) -> Generator[Message, None, None]:
    """(topic, event times, record time) for every decodable message of ``chosen``, in bag order; counts
    the rest.
    ``envelope``: also when the host had each message (``_host_time``); ``window``: only the
    messages recorded in it (``BagReader.window_ns``)."""
    decoders = {t: decoder_for(m) for t, m in chosen.items()}
    stamped: dict[str, bool] = {}
    ros1 = reader.storage is Storage.ROS1  # its messages read as they are, converted where the decoder needs it
    # ROS 1 bytes decoded as they are only where the bag defines the type as the adapters convert it
    store = reader.typestore
    direct = {t for t, m in chosen.items() if store is not None and adapters_convert(store, m)}
    try:
        for conn, record_ns, raw in reader.messages(chosen, window=window, native=ros1):
            topic = conn.topic
            rep = reports[topic]
            rep.messages += 1
            if progress is not None:
                progress(1)
            decoder = decoders[topic]
            try:
                t = decoder.decode_ros1_times(raw) if topic in direct and rep.model else None
                if t is None:
                    cdr = reader.converted(raw, conn.msgtype) if ros1 else raw
                    if isinstance(cdr, Unconverted):  # a ROS 1 message that is not what its definition says
                        raise MessageError(cdr.error)
                    if rep.model:
                        t = decoder.decode_times(cdr)
                    else:  # its first message: what camera it is, from its fields
                        view, events = decoder.decode(cdr)
                        rep.model, t = camera_model(rep.msgtype, view), events.t
            except MessageError as exc:
                rep.undecodable += 1
                rep.first_error = rep.first_error or str(exc)
                continue
            rep.events += int(t.size)
            if envelope is not None and t.size:
                _host_time(envelope, stamped, topic, t, record_ns, read_stamp(raw))
            yield topic, t, record_ns
    finally:  # also when the caller stops early (the paper's loop, once all are accepted)
        for topic, dec in decoders.items():
            reports[topic].anomalies = dict(dec.anomalies)


def _host_time(envelope: HostEnvelope, stamped: dict[str, bool], topic: str, t: np.ndarray, record_ns: int,
               stamp_ns: int) -> None:
    """One message into the host envelope: its header.stamp against its first event when the driver
    stamps with the host clock (within 1 s of the record time at the topic's first message, as
    metavision_driver and libcaer_driver do), else its record time against its last event."""
    if topic not in stamped:
        stamped[topic] = abs(stamp_ns - record_ns) < 1_000_000_000
    if stamped[topic]:
        envelope.add(topic, int(t[0]), stamp_ns)
    else:
        envelope.add(topic, int(t[-1]), record_ns)


@dataclass
class Recorder(HostEnvelope):
    """A host envelope that keeps each ``add`` to be made again in the process that fits it."""

    calls: list[tuple[str, int, int]] = field(default_factory=list)

    def add(self, topic: str, event_ns: int, host_ns: int) -> None:
        self.calls.append((topic, event_ns, host_ns))


@dataclass
class _Batch:
    """Messages gathered for one block, and what was read and recorded with them."""

    messages: list[Message] = field(default_factory=list)
    nbytes: int = 0

    def fill(self, out: bytearray | memoryview, meta: tuple[Any, ...]) -> tuple[int, tuple[Any, ...] | None]:
        """Every message's times into ``out`` one after another; meta as given, then each message's
        least and greatest time (None: too small)."""
        if len(out) < self.nbytes:
            if not isinstance(out, bytearray):
                return self.nbytes, None
            out.extend(bytes(self.nbytes - len(out)))
        times = np.frombuffer(out, np.int64, count=self.nbytes // 8)
        if self.messages:
            np.concatenate([m[1] for m in self.messages], out=times)
        return self.nbytes, (*meta, *_bounds(times, meta[1]))


def _bounds(times: np.ndarray, counts: np.ndarray) -> tuple[list[int], list[int]]:
    """Each message's least and greatest time (0 for a message with none) of a batch's ``times``, the
    messages' one after another (``counts`` each): two passes over the batch, not two per message."""
    lo, hi = np.zeros(counts.size, np.int64), np.zeros(counts.size, np.int64)
    some = counts > 0
    if some.any():
        starts = (np.cumsum(counts) - counts)[some]
        lo[some] = np.minimum.reduceat(times, starts)
        hi[some] = np.maximum.reduceat(times, starts)
    return lo.tolist(), hi.tolist()


def batches(messages: Iterator[Message], *, models: Callable[[], dict[str, str]], read: list[int],
            recorder: Recorder | None) -> Iterator[pipeline.Block]:
    """``messages`` in blocks (in the child): each block's bytes its messages' times, its meta
    (topic of each, count of each, record time of each, the topics' models so far, messages read
    since the last block, the envelope's adds since the last block). ``read[0]``: messages read so
    far (taken and reset at each block); ``models()``: each topic's model as known now."""
    batch = _Batch()  # holds its messages' times until its block is made: the decoders give each its own array

    def block(batch: _Batch) -> pipeline.Block:
        topics = [m[0] for m in batch.messages]
        counts = np.array([m[1].size for m in batch.messages], np.int64)
        records = np.array([m[2] for m in batch.messages], np.int64)
        meta = (topics, counts, records, models(), read[0], list(recorder.calls) if recorder is not None else [])
        read[0] = 0
        if recorder is not None:
            recorder.calls.clear()
        return pipeline.Block(lambda out: batch.fill(out, meta))

    for message in messages:
        if batch.messages and (batch.nbytes + message[1].nbytes > pipeline.SLOT_BYTES
                               or len(batch.messages) >= BATCH_MESSAGES):
            yield block(batch)
            batch = _Batch()
        batch.messages.append(message)
        batch.nbytes += message[1].nbytes
    if batch.messages or read[0] or (recorder is not None and recorder.calls):
        yield block(batch)


def unpack(data: memoryview | bytes, meta: tuple[Any, ...]) -> tuple[Iterator[Bounded], dict[str, str], int,
                                                                     list[tuple[str, int, int]]]:
    """(the block's messages, their times views of one copy of the block's, with their least and
    greatest time; the topics' models; messages read; the envelope's adds) of a block ``batches`` made."""
    topics, counts, records, models, read, calls, least, greatest = meta
    times = np.frombuffer(data, np.int64, count=int(counts.sum())).copy()  # the slot is used again

    def messages() -> Iterator[Bounded]:
        at = 0
        for topic, n, record_ns, lo, hi in zip(topics, counts.tolist(), records.tolist(), least, greatest):
            yield topic, times[at:at + n], record_ns, lo, hi
            at += n

    return messages(), models, read, calls


def read_ahead(reader: BagReader, feed: Callable[..., None], reports: dict[str, TopicReport],
               envelope: HostEnvelope | None, topics: Mapping[str, str], *, window: tuple[int, int] | None,
               tick: Callable[[int], None]) -> None:
    """``estimate_bag``'s read of ``topics``, each message given to ``feed``, with ``decoded`` run in a
    forked process (``batches``, ``BagReader.deliver``): the same messages fed in the same order, the
    same reports (the child's, taken back at the end; each topic's model before its first message)
    and envelope (its adds made again here)."""
    read = [0]
    recorder = Recorder() if envelope is not None else None
    mine = {t: TopicReport(m) for t, m in topics.items()}  # the child's to fill

    def counted(n: int) -> None:
        read[0] += n

    messages = decoded(reader, topics, mine, counted, recorder, window)
    blocks = batches(messages, models=lambda: {t: r.model for t, r in mine.items() if r.model}, read=read,
                     recorder=recorder)

    def use(data: memoryview | bytes, meta: tuple[Any, ...]) -> None:
        batch, models, n_read, calls = unpack(data, meta)
        for topic, model in models.items():
            reports[topic].model = model
        for message in batch:
            feed(*message)
        if envelope is not None:
            for call in calls:
                envelope.add(*call)
        tick(n_read)

    reports.update(reader.deliver(blocks, use, result=lambda: mine, forked=True))
