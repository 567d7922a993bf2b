"""Where a camera's windows are searched: its prior (arrival times or its events alone, ``evidence``),
the line it is locked on, and the events-placed windows beside its own while they are needed. numpy only."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

from evsync_ros.core.engine.arrival import prior_ns
from evsync_ros.core.engine.evidence import arrival_doubt, choose, may_vote, settled, vote
from evsync_ros.core.engine.lock import State
from evsync_ros.core.engine.methods.refined import Alt, Windows
from evsync_ros.core.engine.stream import CameraStream
from evsync_ros.core.results import CameraFit, Method, Prior, PriorChoice

if TYPE_CHECKING:
    from evsync_ros.core.engine.engine import Engine

__all__ = ['alt', 'arrival_prior', 'centre', 'doubt', 'events_prior', 'placed', 'prior', 'said']


def _on_grid(e: Engine, value: float) -> int:
    g = e.params.grid_ns
    return int(round(value / g)) * g


def placed(e: Engine, s: CameraStream) -> Prior:
    """What places the camera's windows: its arrival times where the feeder has them and the events
    alone are not asked for (``EngineParams.prior``), else its events."""
    return Prior.EVENTS if e.params.prior is PriorChoice.EVENTS or s.last_receipt is None else Prior.ARRIVAL


def arrival_prior(e: Engine, s: CameraStream) -> int | None:
    """The camera's offset its arrival times give (``arrival.prior_ns``; None: not known)."""
    ref = e.stream(e.reference)
    return 0 if s is ref else prior_ns(s.arrival, ref.arrival, grid_ns=e.params.grid_ns)


def events_prior(e: Engine, s: CameraStream) -> int | None:
    """The camera's offset its first events give against the reference's (the cameras began about
    together), on the grid (None: one has no event yet)."""
    ref = e.stream(e.reference)
    if ref.first_ns is None or s.first_ns is None:
        return None
    return _on_grid(e, ref.first_ns - s.first_ns)


def prior(e: Engine, s: CameraStream) -> int | None:
    """Where the camera's windows are searched before a line is accepted: given by the feeder, else where
    ``placed`` says (the reference: 0)."""
    if s.topic == e.reference:
        return 0
    if s.fixed_prior_ns is not None:
        return _on_grid(e, s.fixed_prior_ns)
    return events_prior(e, s) if placed(e, s) is Prior.EVENTS else arrival_prior(e, s)


def centre(e: Engine, s: CameraStream) -> int | None:
    """Where a new window of the camera is searched: the line it is locked on (at its anchor; the
    refined method's windows follow what they find), else its prior (a seed is checked, not trusted)."""
    c = s.lock.correction
    if c is not None and e.params.method is Method.REFINED and s.lock.state is not State.SEEDED:
        return _on_grid(e, c.offset_ns)
    return prior(e, s)


def doubt(e: Engine, s: CameraStream) -> str:
    """Why the arrival times of the camera or the reference are not one clock's arrivals before any
    window says so ('' when nothing does; ``evidence.arrival_doubt``)."""
    ref = e.stream(e.reference)
    return (arrival_doubt(s.arrivals, s.late)
            or arrival_doubt(ref.arrivals, ref.late).replace('its', "the reference's", 1))


def said(e: Engine, s: CameraStream, own: CameraFit, other: CameraFit | None = None) -> CameraFit:
    """A camera's decision with what placed it said: ``evidence.choose`` between ``own``, its windows
    placed as ``prior`` places them, and ``other``, its events-placed windows' decision where tried."""
    if s.fixed_prior_ns is not None:  # placed by the driver, which says by what
        return own
    kind = placed(e, s)
    if kind is Prior.EVENTS or e.params.method is Method.PAPER:
        why = '' if kind is Prior.ARRIVAL else (
            'no arrival times' if s.last_receipt is None else 'the events alone were asked for')
        return replace(own, prior=kind, prior_reason=why)
    return choose(own, other, arrival_ns=arrival_prior(e, s), at_ns=s.bins.last_ns or 0, doubt=doubt(e, s))


def alt(e: Engine, s: CameraStream, w: Windows) -> Alt | None:
    """The camera's windows placed by its events alone and searched over the full range (``evidence``),
    while its own decision under the arrival prior does not stand and the driver fits them beside its
    own; None when they are not needed. Once they agree on a line, they follow it."""
    arrival, events = arrival_prior(e, s), events_prior(e, s)
    if (not e.driver.places_alongside or e.params.method is not Method.REFINED
            or e.params.prior is not PriorChoice.AUTO or s.fixed_prior_ns is not None or s.last_receipt is None
            or arrival is None or events is None or settled(w.decision, arrival, s.bins.last_ns or 0)):
        w.alt = None
        return None
    if w.alt is None:
        w.alt = Alt(centre_ns=events)
    found = w.alt.estimate
    if found is not None and found.accepted:
        w.alt.centre_ns = _on_grid(e, found.offset_ns)
    elif found is not None and w.alt.voted and may_vote(found):  # refused where the vote put them: searched
        # widely again, from the events, that offset not voted for again (two windows' peaks meet by chance)
        w.alt = Alt(centre_ns=events, refused=(*w.alt.refused, w.alt.centre_ns))
    elif found is not None and may_vote(found):  # placed again where their peaks point
        voted = vote(w.alt.fits.values(), lobe_ns=e.params.refined.lobe_margin_ns, away_from=w.alt.refused)
        if voted is not None:
            w.alt = Alt(centre_ns=_on_grid(e, voted), voted=True, refused=w.alt.refused)
    return w.alt
