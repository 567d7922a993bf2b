import numpy as np
import pytest

from evsync_ros.core.engine.arrival import ArrivalTrack

MS = 1_000_000
S = 1_000_000_000


def messages(seed):
    """4 s of 1 ms messages of a camera whose clock runs 300 ppm apart from the arrivals' (a replay's
    pace), arriving 0.5-3 ms after their last event, one in 41 70 ms late (and three early ones 55
    ms), and at 2.5 s its clock stepping 3 s forward: (arrival, last event time) of each."""
    rng = np.random.default_rng(seed)
    event = 5 * S + np.arange(4000, dtype=np.int64) * MS
    arrival = 1_700_000_000 * S + event + np.rint(300e-6 * (event - event[0])).astype(np.int64)
    arrival += rng.integers(MS // 2, 3 * MS, event.size)
    arrival[np.arange(event.size) % 41 == 7] += 70 * MS
    arrival[[20, 30, 40]] += 55 * MS  # in the line's second bucket: late only once it has two points
    event[2500:] += 3 * S
    return arrival, event


def state(track):
    return {k: list(v) if k == '_points' else v for k, v in vars(track).items()}


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_a_steady_line_takes_many_messages_as_it_takes_them_one_by_one(seed):
    """``ArrivalTrack.steady``: each message's far limits and lateness, and the line after them, as
    ``add`` gives them message by message; None, the line untouched, for messages with a jump."""
    arrival, event = messages(seed)
    one, many = ArrivalTrack(jump_ns=S, reach_ns=10 * S), ArrivalTrack(jump_ns=S, reach_ns=10 * S)
    sizes = np.random.default_rng(seed).integers(1, 40, 400)
    starts = np.r_[0, np.cumsum(sizes)]
    batches = taken = refused_with_a_jump = 0
    for a, b in zip(starts[:-1], starts[1:]):
        if a >= arrival.size:
            break
        batches += 1
        verdicts = [one.add(int(t), int(e)) for t, e in zip(arrival[a:b], event[a:b])]
        before = state(many)
        steady = many.steady(arrival[a:b], event[a:b])
        if steady is None:
            assert state(many) == before
            refused_with_a_jump += any(v.jumped_ns is not None for v in verdicts)
            for t, e in zip(arrival[a:b], event[a:b]):
                many.add(int(t), int(e))
        else:
            taken += 1
            assert steady.floor_ns.tolist() == [v.floor_ns for v in verdicts]
            assert steady.ceiling_ns.tolist() == [v.ceiling_ns for v in verdicts]
            assert steady.late == sum(v.late for v in verdicts)
            many = steady.track
        assert state(many) == state(one)
    assert taken > 0.8 * batches and refused_with_a_jump == 1
    assert one.messages < 2000  # the line started over at the jump
