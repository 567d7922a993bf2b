"""The offline driver: a recording read whole, decided once at its end by the same decision and the
same clock-step rule as live, with what only the end allows (docs/method.md, "What only offline
does"). numpy only."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import replace
from typing import TYPE_CHECKING

from evsync_ros.core.engine.jumps import jumped, unmatched
from evsync_ros.core.engine.placement import placed, prior, said
from evsync_ros.core.engine.stream import CameraStream, Job
from evsync_ros.core.errors import StreamError
from evsync_ros.core.host import clock_jumps
from evsync_ros.core.results import CameraFit, Method, Prior, Reason

if TYPE_CHECKING:
    from evsync_ros.core.engine.engine import Engine

__all__ = ['Offline']


class Offline:
    """Fit as the recording is read, decide at its end (``finish``)."""

    keeps_curves = True
    """Each camera's clearest window keeps its curve and counts, for the report's plots."""
    places_alongside = False
    """A camera's events-placed windows come from a later read (``passes``), not beside its own."""

    @staticmethod
    def keep_ns(e: Engine) -> int:
        """Bins kept behind each stream's newest event: once the windows are as long as they get, no
        window is fitted again, and the bins of the windows not yet fitted are all that is needed
        (memory follows the window); before, those live keeps."""
        p, ref = e.params, e.stream(e.reference).bins
        if ref.first_ns is not None and ref.last_ns is not None and (
                ref.last_ns - ref.first_ns >= p.refined.windows_wanted * p.window_ns):
            return 2 * p.window_ns + 2 * p.reach_ns
        return p.drift_span_ns + 2 * p.window_ns + 2 * p.reach_ns

    def tick(self, e: Engine, now_ns: int | None) -> None:
        """A recording has no silence."""

    @staticmethod
    def jobs(e: Engine, s: CameraStream) -> list[Job]:
        """A camera's windows ready to fit (those only its end allows, at ``finish``)."""
        return e.method.jobs(e, s)

    def after_step(self, e: Engine, fitted: Iterable[CameraStream]) -> None:
        """Nothing is decided before the end."""

    def finish(self, e: Engine) -> dict[str, CameraFit]:
        """Every stream has ended: the windows their ends allow are fitted (what live cannot know), and
        each camera's decision is made over all of its windows since its last step; a clock step that
        the windows or the arrival times show refuses it (no one line holds the recording).
        StreamError: a stream had no event."""
        empty = [s.topic for s in e.streams if s.bins.origin_ns is None]
        if empty:
            raise StreamError(f'no events to estimate from on {", ".join(sorted(empty))}')
        e.ended = True
        e.step()
        e.fit([job for s in e.cameras for job in e.method.at_end(e, s)])
        for d in e.method.decide(e, e.cameras):
            d.stream.estimate = e.method.finished(d.stream, d.own)
        out = {s.topic: said(e, s, _where(e, s, s.estimate if s.estimate is not None else _undecided(e, s)))
               for s in e.cameras}
        return _jumped(e, out)


def _jumped(e: Engine, out: dict[str, CameraFit]) -> dict[str, CameraFit]:
    """Each camera whose clock jumped against the reference's, as its arrival times show, refused: by
    its least lags (``host.clock_jumps``), or its lag line's jumps that the reference's do not match."""
    spans = {s.topic: span for s in e.streams if (span := e.first_last(s.topic)) is not None}
    for topic, (at_ns, by_ns) in clock_jumps(e.envelope.within(spans), e.reference).items():
        out[topic] = jumped(out[topic], at_ns=at_ns, by_ns=by_ns, first_ns=spans[topic][0])
    ref = e.stream(e.reference)
    for s in e.cameras:
        own = unmatched(s.jumps_seen, ref.jumps_seen, e.params.jump_ns)
        theirs = unmatched(ref.jumps_seen, s.jumps_seen, e.params.jump_ns)
        if own or theirs:
            _, at, by = own[0] if own else (0, theirs[0][1], -theirs[0][2])
            out[s.topic] = jumped(out[s.topic], at_ns=at, by_ns=by, first_ns=0)
    return out


def _where(e: Engine, s: CameraStream, fit: CameraFit) -> CameraFit:
    """A camera not accepted, its reason saying where it was searched (where its arrival times put it
    against its first events' difference: a prior far from the first events' is worth knowing)."""
    ref, at = e.stream(e.reference), prior(e, s)
    if (fit.accepted or at is None or s.fixed_prior_ns is not None or s.last_receipt is None
            or e.params.method is Method.PAPER):
        return fit
    shift = e.params.refined.max_shift_ns / 1e9
    if placed(e, s) is Prior.EVENTS:
        return replace(fit, reason=f'{fit.reason} (searched within {shift:g} s of where its first events put it)')
    where = f'searched within {shift:g} s of where its arrival times put it'
    if ref.first_ns is not None and s.first_ns is not None:
        where += f', {(at - (ref.first_ns - s.first_ns)) / 1e9:+.3f} s from where its first events do'
    return replace(fit, reason=f'{fit.reason} ({where})')


def _undecided(e: Engine, s: CameraStream) -> CameraFit:
    return CameraFit(topic=s.topic, offset_ns=prior(e, s) or 0, skew_ppm=0.0, anchor_ns=0, accepted=False,
                     cost=math.inf, confidence=0.0, window_ns=(0, 0),
                     reason='too short: no window with events of both cameras', kind=Reason.TOO_SHORT)
