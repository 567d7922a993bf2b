"""The paper's loop fed a chunk at a time, with memory that follows the estimation window. numpy only.
A front end calls ``add(topic, times)`` per message in the order they come, then ``finish()``
(docs/method.md, "Streaming"). The refined method streams through the engine (``core.engine``)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

from evsync_ros.core.bins import BinnedStream, known
from evsync_ros.core.density import TimeArray
from evsync_ros.core.errors import StreamError
from evsync_ros.core.paper import PaperEstimate, PaperParams, WindowResult, estimate_window_counts
from evsync_ros.core.results import WindowFit


def _far(bins: Mapping[str, BinnedStream]) -> dict[str, int]:
    return {t: b.far_events for t, b in bins.items() if b.far_events}


def _next_window(bins: BinnedStream, origin_ns: int, k: int, window_ns: int) -> int | None:
    """``k`` if window k (of ``window_ns`` from ``origin_ns``) holds an event, else the next window that
    does (None: no event after it yet)."""
    start = origin_ns + k * window_ns
    nxt = bins.next_event_ns(start)
    if nxt is None:
        return None
    return k if nxt < start + window_ns else (nxt - origin_ns) // window_ns


def _peak(fit: WindowFit) -> float:
    return -math.inf if math.isnan(fit.peak) else fit.peak


class PaperStream:
    """The paper's loop for every camera against ``reference``, streamed (module notes)."""

    def __init__(self, topics: Iterable[str], *, reference: str, params: PaperParams = PaperParams()) -> None:
        topics = list(topics)
        if reference not in topics:
            raise StreamError(f'reference stream {reference!r} is not among {sorted(topics)}')
        self.params = params
        self.reference = reference
        self.bins = {t: BinnedStream(grid_ns=params.tau_ns) for t in topics}
        self.windows: dict[str, list[WindowResult]] = {t: [] for t in topics if t != reference}
        self.accepted: set[str] = set()
        self.ended: set[str] = set()
        self.next_k: dict[str, int] = {}
        """Per camera, the next window to try."""

    @property
    def nbytes(self) -> int:
        """Bytes of bins held now."""
        return sum(b.nbytes for b in self.bins.values())

    @property
    def far_events(self) -> dict[str, int]:
        """Events far from the rest of their message (corrupt times: counted, not used), per stream."""
        return _far(self.bins)

    @property
    def done(self) -> bool:
        """Every camera has an accepted window: nothing later can change the result."""
        return len(self.accepted) == len(self.windows)

    def add(self, topic: str, times: TimeArray) -> None:
        if topic not in self.bins:
            raise StreamError(f'{topic!r} is not a stream of this estimate')
        if topic in self.accepted or times.size == 0:
            return
        self.bins[topic].add(times)
        self._run()

    def _has(self, topic: str, k: int) -> bool:
        b = self.bins[topic]
        return (b.origin_ns is not None and b.last_ns is not None
                and b.origin_ns + (k + 1) * self.params.window_ns <= b.last_ns + 1)

    def _run(self, final: bool = False) -> None:
        T = self.params.window_ns
        ref = self.bins[self.reference]
        for topic, wins in self.windows.items():
            if topic in self.accepted:
                continue
            cam = self.bins[topic]
            while True:
                k = self.next_k.get(topic, 0)
                whole = self._has(self.reference, k) and self._has(topic, k)
                if not whole and not (final and k == 0 and ref.origin_ns is not None and cam.origin_ns is not None):
                    break  # only whole windows, but a recording shorter than T gets its one partial window
                if whole:  # a window in which either stream has no event is stepped over (a clock jump, a gap)
                    nr = _next_window(ref, known(ref.origin_ns, self.reference), k, T)
                    nc = _next_window(cam, known(cam.origin_ns, topic), k, T)
                    if nr is None or nc is None:
                        break
                    if max(nr, nc) > k:
                        self.next_k[topic] = max(nr, nc)
                        continue
                self.next_k[topic] = k + 1
                n = self.params.n_bins
                ref_start = known(ref.origin_ns, self.reference) + k * T
                cam_start = known(cam.origin_ns, topic) + k * T
                w = estimate_window_counts(ref.counts(ref_start, self.params.tau_ns, n),
                                           cam.counts(cam_start, self.params.tau_ns, n),
                                           ref_start_ns=ref_start, cam_start_ns=cam_start,
                                           index=k, params=self.params)
                wins.append(w)
                cam.drop_before(cam_start + T)
                if w.accepted:
                    self.accepted.add(topic)
                    cam.drop_before(known(cam.last_ns, topic) + 1)
                    break
        pending = [self.next_k.get(t, 0) for t in self.windows if t not in self.accepted]
        if ref.origin_ns is not None:
            ref.drop_before(ref.origin_ns + (min(pending) if pending else 1 << 40) * T)

    def finish(self) -> dict[str, PaperEstimate]:
        empty = [t for t, b in self.bins.items() if b.origin_ns is None]
        if empty:
            raise StreamError(f'no events to estimate from on {", ".join(sorted(empty))}')
        self._run(final=True)
        out = {}
        for topic, wins in self.windows.items():
            chosen = wins[-1] if wins[-1].accepted else min(wins, key=lambda w: w.cost)
            out[topic] = PaperEstimate(chosen.offset_ns, chosen.accepted, chosen.cost, chosen, tuple(wins))
        return out
