"""The scheduler: window lengths from the span, whole windows without overlap, what a stream covers."""

from typing import Any

import numpy as np
import pytest

from evsync_ros.core.errors import ParameterError
from evsync_ros.core.schedule import coverage, plan, window_length_ns

MS = 1_000_000
S = 1_000_000_000
KW: dict[str, Any] = dict(window_ns=10 * S, min_window_ns=250 * MS, windows_wanted=5, tau_ns=MS)


@pytest.mark.parametrize(('span_s', 'live_s'), [(0.3, 0.25), (2.0, 0.25), (3.0, 0.5), (10.8, 2.0), (12.0, 2.0),
                                                (40.0, 5.0), (60.0, 10.0), (3600.0, 10.0)])
def test_the_live_length_is_the_longest_ladder_step_giving_the_windows_wanted(span_s, live_s):
    assert window_length_ns(int(span_s * S), **KW) == int(live_s * S)


@pytest.mark.parametrize('span_s', [0.3, 2.0, 3.0, 10.8, 12.0, 40.0, 60.0, 105.0, 3600.0])
def test_offline_windows_fill_the_span_whole_and_never_exceed_the_window(span_s):
    span = int(span_s * S)
    length = window_length_ns(span, **KW, tile=True)
    count = span // length
    assert length % MS == 0 and length <= KW['window_ns']
    assert count >= min(KW['windows_wanted'], span // KW['min_window_ns'])
    assert span - count * length < max(length // count, MS) + count * MS  # no more than rounding is left


def test_a_span_shorter_than_one_window_gets_the_shortest():
    assert window_length_ns(100 * MS, **KW) == 250 * MS
    assert window_length_ns(100 * MS, **KW, tile=True) == 250 * MS


def test_bad_lengths_are_refused():
    with pytest.raises(ParameterError, match='min_window_ns'):
        window_length_ns(S, window_ns=MS, min_window_ns=2 * MS, windows_wanted=5, tau_ns=MS)
    with pytest.raises(ParameterError, match='tau'):
        window_length_ns(S, window_ns=10 * S, min_window_ns=250 * MS, windows_wanted=5, tau_ns=3 * MS)


def test_plan_gives_whole_windows_that_do_not_overlap():
    starts = plan(1000, 1000 + 10 * S - 1, 3 * S)
    assert starts == [1000, 1000 + 3 * S, 1000 + 6 * S]  # the last 1 s is not a whole window
    assert plan(0, S - 2, S) == []


def test_coverage_excludes_before_the_first_and_after_the_last_event_and_long_gaps():
    counts = np.ones(100)
    counts[40:70] = 0  # a 30 ms pause
    counts[80:83] = 0  # a 3 ms lull: still covered
    mask = coverage(counts, start_ns=0, bin_ns=MS, first_ns=10 * MS + 5, last_ns=90 * MS, gap_ns=20 * MS)
    assert not mask[:10].any() and mask[10:40].all()
    assert not mask[40:70].any() and mask[70:91].all() and not mask[91:].any()
    unbounded = coverage(counts, start_ns=0, bin_ns=MS, first_ns=None, last_ns=None, gap_ns=20 * MS)
    assert unbounded[:40].all() and unbounded[80:].all()
