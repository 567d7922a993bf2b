"""Trigger edges: what a camera's trigger-in recorded, on the same timeline as its events.

Which encodings carry them and how their times are placed: docs/messages.md ("Trigger edges").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

RISING = 1
"""An edge's ``value`` when the input went high (evt3 EXT_TRIGGER bit 0, the ``trigger`` encoding's bit 63)."""
FALLING = 0


@dataclass(frozen=True, slots=True)
class TriggerEdges:
    """Trigger edges in stream order: times (int64 ns on the camera's timeline, as its events),
    edge values (uint8: 1 rising, 0 falling) and channel ids (uint16: the trigger input they came in on)."""

    t: npt.NDArray[np.int64]
    value: npt.NDArray[np.uint8]
    channel: npt.NDArray[np.uint16]

    @classmethod
    def empty(cls) -> TriggerEdges:
        """No edges (one shared read-only instance: most messages have none)."""
        return NO_EDGES

    @classmethod
    def concatenate(cls, parts: Sequence[TriggerEdges]) -> TriggerEdges:
        """The edges of ``parts``, one after the other."""
        if not parts:
            return cls.empty()
        return cls(np.concatenate([p.t for p in parts]), np.concatenate([p.value for p in parts]),
                   np.concatenate([p.channel for p in parts]))

    def __len__(self) -> int:
        return int(self.t.size)

    def on_channel(self, channel: int) -> TriggerEdges:
        """The edges that came in on ``channel``."""
        keep = self.channel == channel
        return TriggerEdges(self.t[keep], self.value[keep], self.channel[keep])

    def shifted(self, ns: int) -> TriggerEdges:
        """The same edges, their times ``ns`` later (a new time array)."""
        return TriggerEdges(self.t + np.int64(ns), self.value, self.channel)


def _frozen(dtype: type[np.generic]) -> np.ndarray:
    out = np.empty(0, dtype)
    out.flags.writeable = False
    return out


NO_EDGES = TriggerEdges(_frozen(np.int64), _frozen(np.uint8), _frozen(np.uint16))


class EdgeScratch:
    """Grow-only edge outputs of a word-loop kernel (at most one edge per 16-bit word); decoders
    return copies of the written part."""

    def __init__(self) -> None:
        self.capacity = 0
        self.t = np.empty(0, np.int64)
        self.value = np.empty(0, np.uint8)
        self.channel = np.empty(0, np.uint16)

    def ensure(self, n_words: int) -> int:
        if n_words > self.capacity:
            self.capacity = max(n_words, 2 * self.capacity)
            self.t = np.empty(self.capacity, np.int64)
            self.value = np.empty(self.capacity, np.uint8)
            self.channel = np.empty(self.capacity, np.uint16)
        return self.capacity

    def edges(self, n: int) -> TriggerEdges:
        if n == 0:
            return TriggerEdges.empty()
        return TriggerEdges(self.t[:n].copy(), self.value[:n].copy(), self.channel[:n].copy())
