"""The live driver: the engine fed as messages arrive, deciding at every step and keeping each camera's
lock (silence, re-centring, a clock step followed). docs/method.md, "One engine". numpy only."""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

from evsync_ros.core.engine.decide import decide, stepped_from
from evsync_ros.core.engine.lock import State
from evsync_ros.core.engine.methods import Decision
from evsync_ros.core.engine.placement import said
from evsync_ros.core.engine.stream import CameraStream, Job
from evsync_ros.core.host import JUMP_SEGMENTS, SEGMENT_NS, clock_jumps
from evsync_ros.core.results import CameraFit, Method
from evsync_ros.core.triggers import edge_anchor, tie

if TYPE_CHECKING:
    from evsync_ros.core.engine.engine import Engine

__all__ = ['Live']

STEP_APART_NS = 2 * JUMP_SEGMENTS * SEGMENT_NS
"""A step its arrival times show this far from the one followed last is another (each is seen, and
placed, within the segments either side that ``host.lag_jumps`` compares)."""


class Live:
    """Decide at every step, each camera's lock following its decisions."""

    keeps_curves = False
    """Windows are kept light (what a report draws is the offline driver's)."""
    places_alongside = True
    """A camera's events-placed windows are fitted beside its own while needed (``placement.alt``)."""

    def __init__(self) -> None:
        self.anchor: str | None = None
        """The camera whose trigger edges the others' are tied to, while it can be (``triggers.tie``)."""
        self.now_ns = 0
        """The arrival clock at the newest tick."""

    def keep_ns(self, e: Engine) -> int:
        """Bins kept behind each stream's newest event: the drift span, two windows and two of the wider
        search's reach (windows placed anew, by a lock or by the events alone, refit from them)."""
        p = e.params
        reach = max(p.reach_ns, p.shifted(p.events_shift_ns).reach_ns)
        return p.drift_span_ns + 2 * p.window_ns + 2 * reach

    def tick(self, e: Engine, now_ns: int | None) -> None:
        """A stream with no message for ``silence_ns`` is silent; a locked camera then lost."""
        if now_ns is None:
            return
        self.now_ns = now_ns
        for s in e.streams:
            if s.last_receipt is not None:
                s.silent = now_ns - s.last_receipt > e.params.silence_ns
                self._hushed(s)

    def _hushed(self, s: CameraStream) -> None:
        """A silent camera locked is lost, its last correction kept."""
        if s.silent and s.lock.state is State.LOCKED and s.last_receipt is not None:
            s.lock.state = State.LOST
            s.lock.message = f'silent for {(self.now_ns - s.last_receipt) / 1e9:.1f} s; keeping the last correction'

    @staticmethod
    def jobs(e: Engine, s: CameraStream) -> list[Job]:
        """A camera's windows ready to fit: a silent one's stream has ended as far as anyone can know,
        and its windows are those its end allows, as offline (``method.at_end`` the once it has none)."""
        found = e.method.jobs(e, s)
        return found if found or not s.silent else e.method.at_end(e, s)

    def after_step(self, e: Engine, fitted: Iterable[CameraStream]) -> None:
        """Each camera that fitted a window: its decision, into its lock (a silent one's too: the windows
        its end allows); a clock step its arrival times show first restarts its line there
        (``_arrival_steps``)."""
        asked = list(fitted)
        with e.lock:
            self._arrival_steps(e, asked)
        decisions = e.method.decide(e, asked)
        again = {d.stream.topic: self._restarted(e, d) for d in decisions}
        with e.lock:
            for d in decisions:
                if d.stream.generation == d.generation and d.stream.lock.correction is d.correction:
                    self._settle(e, d, again[d.stream.topic])  # else it changed meanwhile

    def _arrival_steps(self, e: Engine, asked: list[CameraStream]) -> None:
        """The one clock-step rule on arrival times (``host.clock_jumps``: a camera's least arrival lags
        that step against the reference's, as the offline driver reads them), followed: the camera's
        line restarts from the step. The envelope is kept for as long as the bins are."""
        keep = self.keep_ns(e)
        spans = {}
        for s in e.streams:
            if s.bins.first_ns is not None and s.bins.last_ns is not None:
                e.envelope.trim(s.topic, s.bins.last_ns - keep)
                spans[s.topic] = (s.bins.first_ns, s.bins.last_ns)
        if e.params.method is not Method.REFINED or not asked or e.reference not in spans:
            return
        found = clock_jumps(e.envelope.within(spans), e.reference)
        for s in asked:
            centre = e.centre(s)
            if s.topic in found and centre is not None:
                at_ns, by_ns = found[s.topic]
                if s.arrival_step_ns is None or at_ns > s.arrival_step_ns + STEP_APART_NS:  # not one followed
                    s.arrival_step_ns = at_ns
                    e.restart(s, at_ns + centre, by_ns)

    @staticmethod
    def _restarted(e: Engine, d: Decision) -> CameraFit | None:
        """The one clock-step rule (``decide.stepped_from``), followed: a camera whose windows show its
        clock stepped restarts its line where the newest stretch begins, decided on those windows alone."""
        at = stepped_from(d.own)
        if at is None or e.params.method is not Method.REFINED:
            return None
        s = d.stream
        with e.lock:
            kept = [f for f in d.own.windows if f.ref_start_ns >= at]
        return e.runner.run(decide, [(s.topic, kept, e.params.refined, s.known)])[0] if kept else None

    def _settle(self, e: Engine, d: Decision, restarted: CameraFit | None) -> None:
        s, own = d.stream, d.own
        at = stepped_from(own)
        if at is not None and restarted is not None and restarted.accepted:
            c = s.lock.correction
            by = restarted.offset_ns - (c.apply_one(restarted.anchor_ns) - restarted.anchor_ns) if c else None
            if by is None or abs(by) > e.params.step_ns:  # a step of less is the windows' own scatter
                e.restart(s, at, by)
                own = restarted
        e.method.note(s, own, d.alt)
        s.decided = said(e, s, own, d.alt)
        fits = {t.topic: t.decided for t in e.streams if t.decided is not None}
        edges = {t.topic: t.edges.edges for t in e.streams}
        self.anchor = edge_anchor(fits, edges, reference=e.reference, keep=self.anchor)
        s.estimate = tie(s.decided, fits, edges, reference=e.reference, anchor=self.anchor)
        s.lock.decide(s.estimate)
        self._hushed(s)
