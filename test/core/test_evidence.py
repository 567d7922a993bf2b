"""Which evidence places a camera's windows, and which placement decides (issue 50): the rule on
decisions made by hand (``engine.evidence``)."""

from __future__ import annotations

from evsync_ros.core.engine.evidence import AGREE_NS, VOTES, arrival_doubt, choose, settled, vote, voted_params
from evsync_ros.core.refined import CANDIDATES, RefinedParams
from evsync_ros.core.results import CameraFit, Prior, Reason, WindowFit

MS = 1_000_000


def _fit(accepted: bool, offset_ns: int = 0, reason: str = '') -> CameraFit:
    return CameraFit(topic='/b', offset_ns=offset_ns, skew_ppm=0.0, anchor_ns=0, accepted=accepted, cost=0.0,
                     confidence=1.0, window_ns=(0, 1), uncertainty_ns=20_000.0 if accepted else None,
                     reason=reason, kind=Reason.of(reason))


def test_a_decision_under_arrival_times_stands_only_within_50_ms_of_where_they_put_it():
    assert settled(_fit(True, 3 * MS), 0, 0)
    assert not settled(_fit(True, AGREE_NS + 1), 0, 0)
    assert not settled(_fit(False), 0, 0) and not settled(None, 0, 0) and not settled(_fit(True), None, 0)


def test_the_decision_is_the_one_that_stands_else_the_events_alone():
    stands = choose(_fit(True, 2 * MS), _fit(True, 900 * MS), arrival_ns=0, at_ns=0)
    assert stands.prior is Prior.ARRIVAL and stands.offset_ns == 2 * MS and stands.prior_reason == ''
    far = choose(_fit(True, 262 * MS), _fit(True, 262 * MS + 5), arrival_ns=0, at_ns=0)
    assert far.prior is Prior.EVENTS and "not one clock's arrivals" in far.prior_reason
    refused = choose(_fit(False, reason='windows disagree: 3 of 7'), _fit(True, 777 * MS), arrival_ns=0, at_ns=0)
    assert refused.prior is Prior.EVENTS and refused.offset_ns == 777 * MS
    assert '(windows disagree)' in refused.prior_reason
    # the windows found a line, only not where arrival times put it, and the events alone did not
    found = choose(_fit(True, 262 * MS), _fit(False, reason='too short: 2'), arrival_ns=0, at_ns=0)
    assert found.accepted and found.prior is Prior.ARRIVAL and '+262.000 ms' in found.prior_reason
    # neither: the arrival refusal, with what the events alone found after it
    both = choose(_fit(False, reason='windows disagree: a'), _fit(False, reason='too flat: b'), arrival_ns=0, at_ns=0)
    assert not both.accepted and both.reason == 'windows disagree: a; placed by its events alone: too flat: b'
    assert both.kind is Reason.DISAGREE
    # in doubt before any window, the events' refusal speaks
    doubted = choose(_fit(False, reason='windows disagree: a'), _fit(False, reason='too flat: b'), arrival_ns=0,
                     at_ns=0, doubt='most came late')
    assert doubted.prior is Prior.EVENTS and doubted.reason == 'too flat: b'
    assert doubted.prior_reason.endswith('most came late')


def test_arrival_times_are_in_doubt_when_a_quarter_of_the_messages_came_late():
    assert arrival_doubt(100, 25) == '' and 'came more than 50 ms' in arrival_doubt(100, 26)
    assert arrival_doubt(4, 4) == ''  # too few messages to say


def _window(*candidates: int) -> WindowFit:
    return WindowFit(ref_start_ns=0, offset_ns=candidates[0], peak=0.9, confidence=0.1, accepted=False,
                     candidates=tuple((c, 0.9 - 0.1 * k) for k, c in enumerate(candidates)))


def test_windows_vote_for_where_their_peaks_point():
    # each window's best peak is a rival; the true offset is among every window's candidates but one
    windows = [_window(-3 * 10**9, 100 * MS, 7 * MS), _window(4 * 10**9, 100 * MS + 5 * MS),
               _window(2 * 10**9, 99 * MS, -1), _window(-1 * 10**9, 1 * 10**9 + 7)]
    assert abs(vote(windows, lobe_ns=20 * MS) - 100 * MS) <= 5 * MS
    # fewer than VOTES windows pointing at one place: no vote
    assert VOTES == 2 and vote([_window(1 * MS), _window(900 * MS)], lobe_ns=20 * MS) is None
    assert vote([], lobe_ns=20 * MS) is None


def test_a_voted_search_is_narrow_and_judged_over_the_wide_range():
    p = voted_params(RefinedParams(), narrow_ns=500 * MS, wide_ns=5 * 10**9)
    assert p.max_shift_ns == 500 * MS and p.chance_search_ns == 2 * 5 * 10**9 // CANDIDATES
