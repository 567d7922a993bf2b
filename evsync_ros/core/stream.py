"""Both estimators fed a chunk at a time, with memory that follows the estimation window. numpy only.
A front end calls ``add(topic, times)`` per message in the order they come, then ``finish()``
(docs/method.md, "Streaming")."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from evsync_ros.core.bins import BinnedStream, known
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.density import TimeArray
from evsync_ros.core.errors import StreamError
from evsync_ros.core.paper import PaperEstimate, PaperParams, WindowResult, estimate_window_counts
from evsync_ros.core.refined import RefinedParams, fit_window
from evsync_ros.core.results import WindowFit


@dataclass
class _Camera:
    topic: str
    bins: BinnedStream
    prior_ns: int | None
    pending: list[TimeArray] = field(default_factory=list)
    """Chunks that came before the reference's first (the grid is not placed yet)."""
    next_window: int = 0
    busy_window: int = -1
    """The last window known to hold a reference event (bins only gain events before it is fitted, so
    it stays so): the reference is not searched again for it on every message."""
    fits: list[WindowFit] = field(default_factory=list)
    best: WindowFit | None = None


class RefinedStream:
    """The refined estimator's windows for every camera against ``reference``, streamed.

    Windows are laid out as ``refined.window_starts`` lays them out on whole arrays: from the
    reference's first event, contiguous, of the length ``span_ns`` (the recording's expected span,
    e.g. from a bag's metadata) chooses; without one, the longest (``window_ns``). Each window is
    fitted once every stream it needs has passed it, and only its summary is kept
    (``WindowFit.light``; the most confident window whole, for plots). ``priors_ns`` centre each
    camera's search (default: first events); ``corrections`` bin a camera's times through a skew
    (a second pass).
    """

    def __init__(self, topics: Iterable[str], *, reference: str, params: RefinedParams = RefinedParams(),
                 priors_ns: Mapping[str, int] | None = None,
                 corrections: Mapping[str, ClockCorrection] | None = None, span_ns: int | None = None) -> None:
        topics = list(topics)
        if reference not in topics:
            raise StreamError(f'reference stream {reference!r} is not among {sorted(topics)}')
        self.params = params
        self.length_ns = params.window_length(span_ns) if span_ns is not None else params.window_ns
        """The windows' length."""
        self._reach_ns = params.camera_reach_ns
        """Computed once: it is read on every message."""
        self.reference = reference
        self.ref = BinnedStream(grid_ns=params.fine_ns)
        priors, corrections = dict(priors_ns or {}), dict(corrections or {})
        self.cams = {t: _Camera(t, BinnedStream(grid_ns=params.fine_ns, correction=corrections.get(t)),
                                priors.get(t)) for t in topics if t != reference}
        self.done: set[str] = set()
        """Streams that have ended (``end``); finish() ends all."""
        self.windows_fitted = 0

    # -- feeding --------------------------------------------------------------------------------

    def add(self, topic: str, times: TimeArray) -> None:
        """Bin one message's event times (any order) of ``topic``, and fit every window now ready."""
        if times.size == 0:
            return
        if topic == self.reference:
            first = self.ref.origin_ns is None
            self.ref.add(times)
            if first:
                for cam in self.cams.values():
                    for chunk in cam.pending:
                        self._add_cam(cam, chunk)
                    cam.pending.clear()
        else:
            placed = self.cams.get(topic)
            if placed is None:
                raise StreamError(f'{topic!r} is not a stream of this estimate')
            if self.ref.origin_ns is None:
                placed.pending.append(times)
                return
            self._add_cam(placed, times)
        self._fit_ready()

    def _add_cam(self, cam: _Camera, times: TimeArray) -> None:
        ref_origin = known(self.ref.origin_ns, f'{self.reference} origin')
        if cam.bins.origin_ns is None:
            if cam.prior_ns is None:  # cameras started about together, as fit_camera assumes
                near = cam.bins.near(cam.bins.correction.apply(times) if cam.bins.correction else times)
                if near.size == 0:
                    cam.bins.add(times)  # counted as far
                    return
                cam.prior_ns = ref_origin - int(near.min())
            else:  # the grid must put ref_start - prior on it: round the prior to the grid
                f = self.params.fine_ns
                cam.prior_ns = int(round(cam.prior_ns / f)) * f
            cam.bins.origin_ns = ref_origin - cam.prior_ns
        cam.bins.add(times)

    def end(self, topic: str) -> None:
        """``topic`` will send no more events."""
        self.done.add(topic)
        self._fit_ready()

    # -- windows --------------------------------------------------------------------------------

    def _start(self, k: int) -> int:
        return known(self.ref.origin_ns, f'{self.reference} origin') + k * self.length_ns

    def _ref_has(self, k: int) -> bool:
        """Window k lies within the reference's events (as refined.window_starts)."""
        return self.ref.last_ns is not None and self._start(k) + self.length_ns <= self.ref.last_ns + 1

    def _fit_ready(self) -> None:
        if self.ref.origin_ns is None:
            return
        reach = self._reach_ns
        length = self.length_ns
        for cam in self.cams.values():
            if cam.bins.origin_ns is None:
                continue
            while self._ref_has(cam.next_window):
                w = self._start(cam.next_window)
                if cam.busy_window < cam.next_window:
                    nxt = self.ref.next_event_ns(w)
                    if nxt is None:
                        break
                    if nxt >= w + length:  # no reference event in this window: step over the gap
                        cam.next_window = max(cam.next_window + 1, (nxt - self._start(0)) // length)
                        continue
                    cam.busy_window = cam.next_window
                prior = known(cam.prior_ns, f'{cam.topic} prior')
                if cam.topic not in self.done and known(cam.bins.last_ns, cam.topic) < w - prior + length + reach:
                    break
                self._fit(cam, w)
        self._drop()

    def _fit(self, cam: _Camera, w: int) -> None:
        fit = fit_window(self.ref, cam.bins, ref_start_ns=w, length_ns=self.length_ns,
                         prior_ns=known(cam.prior_ns, f'{cam.topic} prior'), params=self.params)
        if cam.best is None or (fit.confidence, _peak(fit)) > (cam.best.confidence, _peak(cam.best)):
            cam.best = fit
        cam.fits.append(fit.light())
        cam.next_window += 1
        self.windows_fitted += 1

    def _drop(self) -> None:
        reach = self._reach_ns
        starts = []
        for cam in self.cams.values():
            if cam.bins.origin_ns is None:
                return  # a camera not yet placed may need the reference from its start
            w = self._start(cam.next_window)
            cam.bins.drop_before(w - known(cam.prior_ns, f'{cam.topic} prior') - reach)
            starts.append(w)
        if starts:
            self.ref.drop_before(min(starts))

    def finish(self) -> dict[str, list[WindowFit]]:
        """End every stream; each camera's windows in order (the most confident one whole).

        Raises:
            StreamError: the reference or a camera had no event at all.
        """
        self.done.update([self.reference, *self.cams])
        if self.ref.origin_ns is None:
            raise StreamError(f'stream {self.reference!r}: no events to estimate from')
        empty = [t for t, c in self.cams.items() if c.bins.origin_ns is None]
        if empty:
            raise StreamError(f'no events to estimate from on {", ".join(sorted(empty))}')
        self._fit_ready()
        out = {}
        for cam in self.cams.values():
            if not cam.fits:  # a reference shorter than one window: its one window from the start
                self._fit(cam, self._start(0))
            best = cam.best
            out[cam.topic] = [best if best is not None and f.ref_start_ns == best.ref_start_ns else f for f in cam.fits]
        return out

    @property
    def nbytes(self) -> int:
        """Bytes of bins held now."""
        return self.ref.nbytes + sum(c.bins.nbytes for c in self.cams.values())

    @property
    def late_events(self) -> dict[str, int]:
        """Events that came after their bins were freed (counted, not used), per stream."""
        out = {self.reference: self.ref.dropped_late}
        out.update({t: c.bins.dropped_late for t, c in self.cams.items()})
        return {t: n for t, n in out.items() if n}

    @property
    def far_events(self) -> dict[str, int]:
        """Events far from the rest of their message (corrupt times: counted, not used), per stream."""
        return _far({self.reference: self.ref, **{t: c.bins for t, c in self.cams.items()}})


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
