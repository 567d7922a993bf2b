"""The arrival clock on sim time (issue 52): between two /clock ticks it moves on at the pace /clock
keeps, never past the next tick, and starts over when /clock goes back."""

from __future__ import annotations

import pytest

pytest.importorskip('rclpy', reason='rclpy is installed by ./dev setup')

from evsync_ros.ros.clock import Ticks

MS = 1_000_000
BAG = 1_700_000_000_000_000_000


def ticked(pace: float, hz: float = 40.0, seconds: float = 2.0) -> Ticks:
    """/clock at ``hz`` of a bag played at ``pace``, taken exactly on time."""
    ticks = Ticks()
    period = round(1e9 / hz)
    for k in range(int(seconds * hz) + 1):
        ticks.add(BAG + round(k * period * pace), 10**12 + k * period)
    return ticks


@pytest.mark.parametrize('pace', [1.0, 0.5, 2.0])
def test_between_ticks_it_moves_at_the_pace_of_the_clock(pace):
    ticks = ticked(pace)
    last_clock, last_steady = BAG + round(80 * 25 * MS * pace), 10**12 + 80 * 25 * MS
    assert ticks.now(last_steady) == last_clock
    assert abs(ticks.now(last_steady + 10 * MS) - (last_clock + round(10 * MS * pace))) <= 1
    # a tick that comes late (a busy player) is not run past: at most one tick's step on
    assert ticks.now(last_steady + 100 * MS) == last_clock + round(25 * MS * pace)


def test_a_paused_clock_stands_and_a_clock_that_goes_back_starts_over():
    ticks = Ticks()
    for k in range(10):  # --start-paused: /clock held at the bag's start
        ticks.add(BAG, k * 25 * MS)
    assert ticks.now(10 * 25 * MS) == BAG
    assert Ticks().now(0) is None  # before the first tick: not known
    ticks = ticked(1.0)
    ticks.add(BAG, 10**12 + 3 * 10**9)  # a loop: back to the bag's start
    assert ticks.now(10**12 + 3 * 10**9 + 10 * MS) == BAG  # one tick: no pace known yet
    ticks.add(BAG + 25 * MS, 10**12 + 3 * 10**9 + 25 * MS)
    assert ticks.now(10**12 + 3 * 10**9 + 35 * MS) == BAG + 35 * MS


def test_a_tick_taken_late_does_not_make_the_arrivals_after_it_early():
    ticks = ticked(1.0)
    last_clock, due = BAG + 81 * 25 * MS, 10**12 + 81 * 25 * MS
    ticks.add(last_clock, due + 8 * MS)  # the executor got to it 8 ms late
    # the line through the ticks taken on time (its pace a little off for the late one), not 8 ms early
    assert abs(ticks.now(due + 10 * MS) - (last_clock + 10 * MS)) < MS // 2


def test_the_pace_is_sure_only_once_measured_since_the_clock_last_stood():
    ticks = Ticks()
    sure = [ticks.sure]
    ticks.add(BAG, 0)
    ticks.add(BAG, 25 * MS)  # paused
    sure.append(ticks.sure)
    assert ticks.now(40 * MS) == BAG
    ticks.add(BAG + 50 * MS, 50 * MS)  # moving again, at a pace not measured yet (here twice 1)
    sure.append(ticks.sure)
    ticks.add(BAG + 100 * MS, 75 * MS)
    sure.append(ticks.sure)
    assert sure == [False, False, False, True]
    assert ticks.now(85 * MS) == BAG + 120 * MS
