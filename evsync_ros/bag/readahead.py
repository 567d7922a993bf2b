"""The estimate's messages read and decoded in a forked process (``pipeline``) while this one bins and
fits them: each batch of messages' event times handed over in shared memory, with what the engine
and the report need of each message (docs/bags.md, "The estimate's read"). The engine is fed the
same times, record times and models in the same order as from ``estimate._event_chunks`` itself."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from evsync_ros.bag import pipeline
from evsync_ros.core.host import HostEnvelope

__all__ = ['BATCH_MESSAGES', 'Bounded', 'Message', 'Recorder', 'batches', 'unpack']

BATCH_MESSAGES = 1024
"""Messages a batch holds at most (and at most ``pipeline.SLOT_BYTES`` of event times)."""

Message = tuple[str, np.ndarray, int]
"""(topic, event times, record time) of a decoded message, as ``_event_chunks`` yields it."""
Bounded = tuple[str, np.ndarray, int, int, int]
"""A ``Message`` with its least and greatest event time, as ``unpack`` gives it."""


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
