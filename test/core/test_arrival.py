"""The arrival-time prior (``arrival.prior_ns``) at any replay pace: a bag played at 2x on the system
clock loses 50 ms of lag per 50 ms bucket of arrivals, and a line not yet fitted must not keep it."""

from __future__ import annotations

import random

import pytest

from evsync_ros.core.engine.arrival import ArrivalTrack, prior_ns

MS = 1_000_000
TRUTH = 1_234 * MS
"""What the camera's times need added to be on the reference's."""


def _messages(pace: float, camera_from_ms: int, seed: int) -> list[tuple[int, str, int]]:
    """1 ms messages of two cameras (arrival, which, last event time) played at ``pace``, arriving 50-300
    µs after their time, the camera's from ``camera_from_ms`` of arrivals on."""
    rnd = random.Random(seed)
    host, epoch = 1_700_000_000 * 10**9, 5 * 10**9
    out = []
    for k in range(1, 1500):
        when = host + int(k * MS / pace)
        out.append((when + rnd.randint(50_000, 300_000), 'reference', epoch + k * MS))
        if when - host >= camera_from_ms * MS:
            out.append((when + rnd.randint(50_000, 300_000), 'camera', epoch + k * MS - TRUTH))
    return sorted(out)


def _worst_prior_error(pace: float, camera_from_ms: int, seed: int) -> int:
    tracks = {w: ArrivalTrack(jump_ns=10**9, reach_ns=10 * 10**9) for w in ('reference', 'camera')}
    worst = 0
    for arrival, which, event in _messages(pace, camera_from_ms, seed):
        tracks[which].add(arrival, event)
        prior = prior_ns(tracks['camera'], tracks['reference'], grid_ns=MS)
        if prior is not None:
            worst = max(worst, abs(prior - TRUTH))
    return worst


@pytest.mark.parametrize('pace', [0.5, 1.0, 2.0, 4.0])
@pytest.mark.parametrize('camera_from_ms', [0, 20, 60, 130])
def test_the_prior_holds_from_the_first_messages_at_any_pace(pace, camera_from_ms):
    # before a line has a slope it is read from its newest message at the other's slope: at 2x a level
    # kept up to 50 ms of lag too many, and at 0.5x a bucket's least lag is its first message's
    for seed in range(3):
        assert _worst_prior_error(pace, camera_from_ms, seed) <= 2 * MS


def _jumps(pace: float, jump_ns: int, step_at: int | None = None, seed: int = 0) -> list[int]:
    """Where one camera's 1 ms messages played at ``pace`` are taken for clock jumps (message numbers),
    its clock stepping 3 ``jump_ns`` forward at message ``step_at``."""
    rnd = random.Random(seed)
    track = ArrivalTrack(jump_ns=jump_ns, reach_ns=10 * 10**9)
    found = []
    for k in range(1, int(2000 * max(1.0, pace))):
        step = 3 * jump_ns if step_at is not None and k >= step_at else 0
        verdict = track.add(10**18 + int(k * MS / pace) + rnd.randint(50_000, 60_000), 5 * 10**9 + k * MS + step)
        if verdict.jumped_ns is not None:
            found.append(k)
    return found


@pytest.mark.parametrize('pace', [0.5, 1.0, 2.0, 4.0, 10.0])
@pytest.mark.parametrize('jump_ns', [10 * MS, 50 * MS, 10**9])
def test_no_pace_is_taken_for_a_clock_jump_and_a_jump_is_found_at_any(pace, jump_ns):
    # a line without a slope judges a message against the newest: at 0.5x with a 10 ms threshold a
    # level took the replay's growing lag for a jump 20 ms into every new line
    assert _jumps(pace, jump_ns) == []
    for step_at in (30, 1500):  # before the line has a slope, and after
        assert _jumps(pace, jump_ns, step_at) == [step_at + 1]  # held once, then confirmed


def _stalled(pace: float, seed: int) -> list[tuple[int, str, int]]:
    """The two cameras' 1 ms messages of ``_messages`` (the camera from the start), taken as a busy host
    takes them: it stalls 0-40 ms every 20-120 ms, and after a stall takes the reference's queue, then
    the camera's, 40 µs a message; the arrival is when a message is taken."""
    rnd = random.Random(seed)
    sent = _messages(pace, 0, seed)[:8000]
    taken: list[tuple[int, str, int]] = []
    queue: list[tuple[int, str, int]] = []
    free, i = sent[0][0], 0
    stall_at = free + rnd.randint(20, 120) * MS
    while i < len(sent) or queue:
        if i < len(sent) and sent[i][0] <= free:
            queue.append(sent[i])
            i += 1
        elif queue:
            queue.sort(key=lambda m: (m[1] != 'reference', m[0]))
            free += 40_000
            taken.append((free, *queue.pop(0)[1:]))
        else:
            free = max(free, sent[i][0])
            if free >= stall_at:
                free += rnd.randint(0, 40) * MS
                stall_at = free + rnd.randint(20, 120) * MS
    return taken


@pytest.mark.parametrize('pace', [0.5, 1.0, 2.0, 4.0])
def test_the_prior_holds_on_a_host_that_takes_messages_in_bursts(pace):
    # two lines refitted at different messages disagreed by up to 139 ms at 4x (26 ms at 2x) when the
    # host took messages in bursts; their buckets' least lags, paired, do not (from 200 ms on: before,
    # neither line has the pace and a burst still moves the prior)
    for seed in range(6):
        tracks = {w: ArrivalTrack(jump_ns=10**9, reach_ns=10 * 10**9) for w in ('reference', 'camera')}
        taken = _stalled(pace, seed)
        worst = 0
        for arrival, which, event in taken:
            tracks[which].add(arrival, event)
            prior = prior_ns(tracks['camera'], tracks['reference'], grid_ns=MS)
            if prior is not None and arrival - taken[0][0] > 200 * MS:
                worst = max(worst, abs(prior - TRUTH))
        assert worst <= MS, (seed, worst)
