"""Which evidence places a camera's windows, and which placement its decision is taken from: one rule
for every front end (docs/method.md, "Record times"). numpy only.

A feeder's arrival times (a bag's record times, the node's clock) put a camera where its lag line
against the reference's says, good to milliseconds, and its windows are searched narrowly about that
(``Prior.ARRIVAL``). That holds only when they are one clock's arrivals: a bag merged from two hosts,
converted from a dataset (record time = header.stamp) or simulated on each camera's clock has record
times that say nothing of the offset. So a camera's decision under the arrival prior is kept only when
it is accepted and its line agrees with that prior (within ``AGREE_NS``: a few paths' latencies, far
below any two unsynchronised clocks' difference); otherwise its windows are also placed from its
events alone (``Prior.EVENTS``: its first events against the reference's, searched over the full
range), and an accepted decision there is taken. ``choose`` is that rule.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

from evsync_ros.core.refined import CANDIDATES, RefinedParams
from evsync_ros.core.results import CameraFit, Prior, Reason, WindowFit

__all__ = [
    'AGREE_NS',
    'LATE_SHARE',
    'RECENTRE_NS',
    'VOTES',
    'arrival_doubt',
    'choose',
    'line_at',
    'may_vote',
    'settled',
    'vote',
    'voted_params',
]

AGREE_NS = 50_000_000
"""A line this far from where the arrival times put the camera is not one clock's arrivals: two paths'
latencies differ by a few milliseconds (one host's bags place every camera within 0.05 ms of the truth
on the rigs of ``studies/record_times.py``; a real host's messages scatter up to 47 ms above their lag
line), and a message 50 ms above its line already counts as late (``arrival.LATE_NS``)."""
RECENTRE_NS = 25_000_000
"""Windows placed this far from the line they agree on (a tenth of the shortest window) are placed
again on it, offline, where a first pass could not (live, the lock re-centres them)."""
LATE_SHARE = 0.25
"""A stream more than this share of whose messages came late (``arrival.LATE_NS`` above its lag line)
does not arrive as one clock's messages do: a real host's scatter stays under 50 ms."""


def line_at(fit: CameraFit, t_ns: int) -> float:
    """The offset a decision's line gives at camera time ``t_ns``."""
    return fit.offset_ns + fit.skew_ppm * 1e-6 * (t_ns - fit.anchor_ns)


def settled(fit: CameraFit | None, arrival_ns: int | None, at_ns: int) -> bool:
    """Whether a decision under the arrival prior stands: accepted, its line at ``at_ns`` (camera time)
    within ``AGREE_NS`` of ``arrival_ns``, the prior there."""
    return (fit is not None and fit.accepted and arrival_ns is not None
            and abs(line_at(fit, at_ns) - arrival_ns) <= AGREE_NS)


def arrival_doubt(messages: int, late: int) -> str:
    """Why a stream's arrival times are not one clock's arrivals before any window is fitted ('' when
    nothing says so): more than ``LATE_SHARE`` of its messages came late."""
    if messages >= 8 and late > LATE_SHARE * messages:
        return (f'{late} of its {messages} messages came more than 50 ms above its arrival-lag line, as no one '
                "clock's arrivals do")
    return ''


def _apart(fit: CameraFit, arrival_ns: int, at_ns: int) -> str:
    return (f'its windows agree {(line_at(fit, at_ns) - arrival_ns) / 1e6:+.3f} ms from where its arrival times put '
            "it: they are not one clock's arrivals")


def choose(arrival: CameraFit | None, events: CameraFit | None, *, arrival_ns: int | None, at_ns: int,
           doubt: str = '') -> CameraFit:
    """A camera's decision from the one under the arrival prior and the one under its events alone
    (None: not tried; the module notes say when each is), with ``prior`` and ``prior_reason`` said:
    the arrival decision when it stands (``settled``), else the events' when accepted, else the
    arrival decision when accepted (its windows found a line, only not where arrival times put it),
    else the refusal of the placement the evidence favours (the events' when the arrival times are
    in doubt or there are none)."""
    if arrival is not None and settled(arrival, arrival_ns, at_ns):
        return replace(arrival, prior=Prior.ARRIVAL, prior_reason='')
    why = (doubt or (_apart(arrival, arrival_ns, at_ns) if arrival is not None and arrival.accepted
                     and arrival_ns is not None else
                     f'the windows its arrival times placed were not accepted ({arrival.reason.split(":")[0]})'
                     if arrival is not None else 'no arrival times'))
    if events is not None and events.accepted:
        return replace(events, prior=Prior.EVENTS, prior_reason=f'placed by its events alone: {why}')
    if arrival is not None and (arrival.accepted or not doubt or events is None):
        reason = why if arrival.accepted else ''
        return replace(arrival, prior=Prior.ARRIVAL, prior_reason=reason, reason=_also(arrival.reason, events))
    assert events is not None
    return replace(events, prior=Prior.EVENTS, prior_reason=f'placed by its events alone: {why}')


def _also(reason: str, events: CameraFit | None) -> str:
    """An arrival refusal's reason, with what the events alone found where they were tried."""
    if not reason or events is None:
        return reason
    return f'{reason}; placed by its events alone: {events.reason}'


VOTES = 2
"""Windows whose coarse peaks must point at one offset for the search to be placed on it."""


def may_vote(fit: CameraFit) -> bool:
    """Whether a refused decision's windows found enough to vote on (they disagree, or agree only in a
    stretch): not too few windows, nor too few with a clear peak."""
    return not fit.accepted and fit.kind not in (Reason.TOO_SHORT, Reason.TOO_FLAT)


def vote(fits: Iterable[WindowFit], *, lobe_ns: int, away_from: tuple[int, ...] = ()) -> int | None:
    """The offset the most windows have a coarse peak near (within ``lobe_ns``, any of their best
    ``CANDIDATES``), when at least ``VOTES`` do: where windows searched widely, each taking its highest
    peak, failed to agree, but several peaks point at one place (a wide search often ranks a rival
    above the true peak). ``away_from``: offsets voted before and refused there, not voted again.
    None: no offset has the votes."""
    peaks = [[offset for offset, _ in f.candidates] for f in fits if f.has_data and f.candidates]
    best: tuple[int, int] | None = None
    for own in peaks:
        for offset in own:
            if any(abs(offset - o) <= lobe_ns for o in away_from):
                continue
            votes = sum(any(abs(other - offset) <= lobe_ns for other in theirs) for theirs in peaks)
            if votes >= VOTES and (best is None or votes > best[0]):
                best = (votes, offset)
    return None if best is None else best[1]


def voted_params(p: RefinedParams, *, narrow_ns: int, wide_ns: int) -> RefinedParams:
    """The search about a voted offset: as narrow as about arrival times (``narrow_ns``), its chance
    judged as for a peak of any of ``CANDIDATES`` per window anywhere in the wide range it was chosen
    from (``wide_ns`` either side): the place was picked by the windows' own peaks."""
    return replace(p, max_shift_ns=narrow_ns, chance_search_ns=2 * wide_ns // CANDIDATES)
