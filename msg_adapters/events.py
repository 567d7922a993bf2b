"""What every adapter returns, and how it counts what it could not decode."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from msg_adapters.edges import TriggerEdges


def byte_view(payload: np.ndarray | bytes | bytearray | memoryview) -> np.ndarray:
    """A flat uint8 numpy view of a payload (no copy)."""
    if isinstance(payload, np.ndarray):
        if payload.dtype == np.uint8 and payload.ndim == 1:
            return payload
        return payload.reshape(-1).view(np.uint8)
    return np.frombuffer(payload, np.uint8)


def whole_units(buf: np.ndarray, unit: int, anomalies: Anomalies, what: str) -> np.ndarray:
    """``buf`` without the trailing bytes that do not make a whole ``unit``; those are counted."""
    extra = buf.size % unit
    if extra:
        anomalies.count(what, extra)
        return buf[: buf.size - extra]
    return buf


@dataclass(slots=True)
class Events:
    """Decoded events: times as int64 ns, and x, y (uint16), polarity (uint8) when asked for."""

    t: np.ndarray
    x: np.ndarray | None = None
    y: np.ndarray | None = None
    p: np.ndarray | None = None

    @classmethod
    def empty(cls, *, xyp: bool) -> Events:
        """No events (with empty x, y and polarity arrays when ``xyp``)."""
        t = np.empty(0, np.int64)
        if not xyp:
            return cls(t)
        return cls(t, np.empty(0, np.uint16), np.empty(0, np.uint16), np.empty(0, np.uint8))

    def __len__(self) -> int:
        return int(self.t.size)


class Stepped(NamedTuple):
    """One message of a live stream through its decoder's ``step`` (``EventPacketDecoder.step``,
    ``EventArrayDecoder.step``): decoded, counted on the estimate's grid and restamped in one C call."""

    times: npt.NDArray[np.int64]
    """Its event times on the camera's timeline: a view of the decoder's scratch, valid until its next call."""
    lo: int
    hi: int
    mid: int
    """Its least, greatest and middle (``times[n // 2]``) event time (0 with no event)."""
    k0: int
    counts: npt.NDArray[np.int32] | None
    """Its events in bins ``k0``, ``k0 + 1`` ... of the grid from time 0 (a view of the caller's
    ``counts``); None when they span more bins than it holds, or there is no event."""
    out: bytes | bytearray | None
    """The message restamped (None: not asked, or ``error``)."""
    error: str
    """Why it could not be restamped ('' when it was, or was not asked)."""
    edges: TriggerEdges | None = None
    """Its trigger edges on the camera's timeline, when asked (``decode_times_edges``'s)."""


class Anomalies(dict[str, int]):
    """Counts of input a decoder could not take as it is, by kind: nothing is dropped unseen."""

    def count(self, what: str, n: int = 1) -> None:
        """Add ``n`` to the count of ``what``."""
        if n:
            self[what] = self.get(what, 0) + int(n)

    def merge(self, counters: np.ndarray, names: tuple[str, ...]) -> None:
        """Move a kernel's counter array into these counts and zero it."""
        for name, n in zip(names, counters.tolist()):
            self.count(name, n)
        counters[:] = 0


class Scratch:
    """Grow-only output buffers of a word-loop kernel: at most ``per_word`` events per 16-bit word.

    Sized from the payload alone, so no counting pass is needed; only the pages the kernel writes
    become resident. Decoders return copies of the written part, never views into the scratch.
    """

    def __init__(self, per_word: int) -> None:
        self.per_word = per_word
        self.capacity = 0
        self.t = np.empty(0, np.int64)
        self.x = np.empty(0, np.uint16)
        self.y = np.empty(0, np.uint16)
        self.p = np.empty(0, np.uint8)

    def ensure(self, n_words: int) -> int:
        need = self.per_word * n_words
        if need > self.capacity:
            self.capacity = max(need, 2 * self.capacity)
            self.t = np.empty(self.capacity, np.int64)
            self.x = np.empty(self.capacity, np.uint16)
            self.y = np.empty(self.capacity, np.uint16)
            self.p = np.empty(self.capacity, np.uint8)
        return self.capacity

    def events(self, n: int, *, xyp: bool) -> Events:
        if not xyp:
            return Events(self.t[:n].copy())
        return Events(self.t[:n].copy(), self.x[:n].copy(), self.y[:n].copy(), self.p[:n].copy())


class WordLoopDecoder:
    """What the C-kernel decoders share (evt3, libcaer_cmp; libcaer and mono for their live messages):
    geometry, state and counter arrays the kernel updates in place, the scratch outputs, and the call
    around the kernel."""

    counter_names: tuple[str, ...] = ()
    per_word = 1

    def __init__(self, *, width: int, height: int, state: list[int]) -> None:
        self.width = int(width)
        self.height = int(height)
        self.anomalies = Anomalies()
        self._state = np.array(state, dtype=np.int64)
        self._counters = np.zeros(len(self.counter_names), dtype=np.int64)
        self._scratch = Scratch(per_word=self.per_word)

    def stands_with(self, other: WordLoopDecoder) -> bool:
        """Whether ``other`` would decode the next payload as this one does: its kind, geometry and state."""
        return (type(other) is type(self) and (other.width, other.height) == (self.width, self.height)
                and bool(np.array_equal(other._state, self._state)))

    def catch_up(self, other: WordLoopDecoder) -> None:
        """A payload ``other`` decoded taken as decoded here too: its state, this one's."""
        self._state[:] = other._state

    def _packet_step(self, kernel: Callable[..., tuple[int, ...] | None], raw: bytes | bytearray | memoryview,
                     unit: int, grid_ns: int, counts: np.ndarray) -> tuple[tuple[int, ...], np.ndarray] | None:
        """kernel(raw, state, counters, width, height, capacity, t, grid_ns, counts): a time_base
        encoding's one call (``_kernels.cmp_packet_step``: what it returns, and the scratch its times
        are in) for a payload of events of at least ``unit`` bytes. None, nothing moved, for a message
        the kernel does not take."""
        sc = self._scratch
        cap = sc.ensure(len(raw) // unit)
        got = kernel(raw, self._state, self._counters, self.width, self.height, cap, sc.t, grid_ns, counts)
        if got is None:
            return None
        if got[1]:
            self.anomalies.merge(self._counters, self.counter_names)
        return got, sc.t

    def _run(self, kernel: Callable[..., tuple[int, int]], payload: np.ndarray | bytes | bytearray | memoryview,
             xyp: bool, *extra: int) -> Events:
        """kernel(words, state, counters, width, height, *extra, capacity, t, x, y, p) on one payload."""
        buf = whole_units(byte_view(payload), 2, self.anomalies, 'odd byte count')
        sc = self._scratch
        cap = sc.ensure(buf.size // 2)
        n, odd = kernel(buf, self._state, self._counters, self.width, self.height, *extra, cap,
                        sc.t, *((sc.x, sc.y, sc.p) if xyp else (None,) * 3))
        if odd:
            self.anomalies.merge(self._counters, self.counter_names)
        return sc.events(n, xyp=xyp)
