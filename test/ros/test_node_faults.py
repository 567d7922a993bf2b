"""evsync_node under faults, its message path fed a 50 s simulated rig at recorded times (``nodefaults``):
a camera silent for 30 s, clock jumps back and forward on both encodings, duplicate and out-of-order
messages, a 10x burst, and a restart. Each time: every distinct message out exactly once, every
camera locked again within 200 us of the truth, the fault reported in /diagnostics."""

from __future__ import annotations

import pytest

pytest.importorskip('rclpy', reason='rclpy is installed by ./dev setup')

from evsync_testing import nodefaults


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    bag = tmp_path_factory.mktemp('rig') / 'rig'
    truth = nodefaults.sim_bag(bag, seconds=50, seed=11)
    return truth, nodefaults.read_messages(bag)


def check(verdict):
    assert verdict.survived, f'{verdict.fault}: ' + '; '.join(verdict.problems)
    assert verdict.lost == verdict.doubled == 0


def test_a_camera_silent_for_30_s_is_reported_lost_and_locks_again(rig):
    check(nodefaults.silent_camera(*rig, seconds=30.0))


@pytest.mark.parametrize('encoding, by_s', [('dvs', -5.0), ('dvs', 7.0), ('evt3', 3.0), ('evt3', -4.0)])
def test_a_clock_jump_is_reported_and_the_new_offset_locked(rig, encoding, by_s):
    check(nodefaults.jumping_clock(*rig, encoding=encoding, by_s=by_s))


def test_duplicates_are_counted_and_not_republished(rig):
    check(nodefaults.duplicated(*rig, seed=1))


def test_out_of_order_messages_are_counted_and_all_go_out(rig):
    check(nodefaults.reordered(*rig, seed=1))


def test_a_burst_of_ten_times_the_events(rig):
    check(nodefaults.bursting(*rig))


@pytest.mark.parametrize('at_s, before_lock', [(3.0, 'hold'), (20.0, 'hold'), (20.0, 'forward')])
def test_a_restarted_node_publishes_what_it_held_and_locks_again(rig, at_s, before_lock):
    check(nodefaults.restarted(*rig, at_s=at_s, before_lock=before_lock))


def test_messages_lost_upstream_are_counted_from_seq_gaps_and_warned(rig):
    check(nodefaults.dropped(*rig, seed=3))
