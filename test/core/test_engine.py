"""The one engine: the same messages with the same arrival times decide alike offline (finish) and live
(step from a timer), at any pace of arrival; the window plan comes from the cameras' own clocks; a
lock follows one rule."""

import math

import numpy as np
import pytest

from evsync_ros.core.engine import Engine, State
from evsync_ros.core.engine.drivers import Offline
from evsync_ros.core.engine.lock import CameraLock
from evsync_ros.core.results import CameraFit, Reason
from evsync_testing.streams import BASE, bursty, thinned

MS = 1_000_000
S = 1_000_000_000


def messages(seconds, clocks, *, seed=3, message_ns=2 * MS, pace=1.0):
    """Every camera's messages in arrival order: (arrival, topic, times). Cameras see one scene; a
    message arrives 0.3-4 ms after its last event, on one host clock; ``pace`` replays it faster."""
    truth = bursty(seconds, seed=seed)
    rng = np.random.default_rng(seed + 100)
    out = []
    for i, (topic, clock) in enumerate(clocks.items()):
        ev = thinned(truth, 0.5, seed=seed + i)
        key = (ev - BASE) // message_ns
        cuts = np.flatnonzero(np.diff(key)) + 1
        for part in np.split(ev, cuts):
            arrival = int(part[-1]) + int(rng.integers(300_000, 4 * MS))
            out.append((BASE + int((arrival - BASE) / pace), topic, clock(part)))
    out.sort(key=lambda m: m[0])
    return out


def offset_clock(offset_ns):
    return lambda t: t - offset_ns


CLOCKS = {'/ref': lambda t: t, '/far': offset_clock(-1000 * S - 123_456),  # a clock 1000 s behind
          '/boot': offset_clock(BASE - 5 * S + 777_000)}  # a sensor clock near 5 s since boot
TRUTH = {'/far': -1000 * S - 123_456, '/boot': BASE - 5 * S + 777_000}


def run_live(msgs, *, step_every_ns=500 * MS):
    eng = Engine(CLOCKS, reference='/ref')
    next_step = msgs[0][0] + step_every_ns
    for arrival, topic, times in msgs:
        eng.add(topic, times, arrival)
        if arrival >= next_step:
            eng.step(arrival)
            next_step += step_every_ns
    eng.step(msgs[-1][0])
    return eng


def run_offline(msgs):
    eng = Engine(CLOCKS, reference='/ref', driver=Offline())
    for k, (arrival, topic, times) in enumerate(msgs):
        eng.add(topic, times, arrival)
        if k % 64 == 0:
            eng.step()
    return eng, eng.finish()


def test_offline_and_live_decide_alike_on_far_apart_epochs():
    msgs = messages(22, CLOCKS)
    live = run_live(msgs)
    _, offline = run_offline(msgs)
    for topic, truth in TRUTH.items():
        off, st = offline[topic], live.status(topic)
        assert off.accepted, off.reason
        assert st.state is State.LOCKED, st.message
        combined = math.hypot(off.uncertainty_ns, st.uncertainty_ns)
        assert abs(st.correction.offset_ns - off.offset_ns) <= 3 * combined
        assert abs(off.offset_ns - truth) <= 3 * off.uncertainty_ns


def test_a_22_s_recording_gets_short_windows_whatever_the_clocks_read():
    # clocks on epochs 1000 s apart planned two 10 s windows: the plan is the reference's own span
    _, offline = run_offline(messages(22, CLOCKS))
    for fit in offline.values():
        assert fit.windows_total >= 5 and {w.length_ns for w in fit.windows} == {2 * S}


@pytest.mark.parametrize('pace', [0.25, 0.5, 2.0, 4.0])
def test_replay_at_another_pace_is_no_jump_and_locks_as_at_1x(pace):
    msgs = messages(16, CLOCKS, pace=pace)
    live = run_live(msgs, step_every_ns=int(500 * MS / pace))
    for topic, truth in TRUTH.items():
        st = live.status(topic)
        assert st.jumps == 0 and st.late_messages == 0
        assert st.state is State.LOCKED, st.message
        assert abs(st.correction.offset_ns - truth) <= 3 * st.uncertainty_ns
    assert live.status('/ref').jumps == 0


def _fit(accepted, reason='', offset_ns=0, se_ns=100_000.0):
    return CameraFit(topic='/b', offset_ns=offset_ns, skew_ppm=0.0, anchor_ns=0, accepted=accepted, cost=0.1,
                     confidence=1.0, window_ns=(0, 1), uncertainty_ns=se_ns if accepted else None, reason=reason,
                     kind=Reason.of(reason))


def state(lock):
    return lock.state  # read through a call: each decide() may change it


def offset(lock):
    return lock.correction.offset_ns


def test_a_lock_never_stands_beside_evidence_that_is_not_accepted():
    lock = CameraLock(margin_ns=20_000)
    lock.decide(_fit(False, 'too short: 2 windows'))
    assert state(lock) is State.ESTIMATING and lock.correction is None
    lock.decide(_fit(True, offset_ns=1_000_000))
    assert state(lock) is State.LOCKED and offset(lock) == 1_000_000
    lock.decide(_fit(False, 'too flat: no clear peak'))  # no evidence is no evidence against
    assert state(lock) is State.LOCKED
    lock.decide(_fit(False, 'uncertain: known only to +-2.2 ms'))
    assert state(lock) is State.LOST and offset(lock) == 1_000_000  # the output does not move
    lock.decide(_fit(True, offset_ns=3_000_000))  # once, far from the correction kept: not yet
    assert state(lock) is State.LOST and offset(lock) == 1_000_000
    lock.decide(_fit(True, offset_ns=3_000_000))  # twice in a row: the new line
    assert state(lock) is State.LOCKED and offset(lock) == 3_000_000
    lock.decide(_fit(False, 'windows disagree: at most 2 of 5'))
    lock.decide(_fit(True, offset_ns=3_050_000))  # agrees with the correction kept: at once
    assert state(lock) is State.LOCKED and offset(lock) == 3_050_000


def test_the_same_messages_lock_the_same_way_twice():
    msgs = messages(14, CLOCKS)
    a, b = run_live(msgs), run_live(msgs)
    for topic in TRUTH:
        assert a.status(topic) == b.status(topic)



def _held(msgs, *, jump_from=None, step_every=None):
    """Run ``msgs`` offline ('/far' 3 s later from message ``jump_from`` on, a step every ``step_every``
    messages), with the bins held measured around every add and before every step; after each step,
    ``peak_nbytes`` is checked against the most measured so far. (engine, the measures)."""
    eng = Engine(CLOCKS, reference='/ref', driver=Offline())
    seen = [0]
    for k, (arrival, topic, times) in enumerate(msgs):
        if topic == '/far' and jump_from is not None and k >= jump_from:
            times = times + 3 * S
        seen.append(eng.nbytes)
        eng.add(topic, times, arrival)
        seen.append(eng.nbytes)
        if step_every is not None and k % step_every == 0:
            seen.append(eng.nbytes)
            eng.step()
            assert eng.peak_nbytes == max(seen)
    return eng, seen


def test_the_peak_of_bins_held_counts_what_a_step_or_a_clock_jump_freed():
    """``peak_nbytes`` is the most bins held at any moment (here measured around every add and before
    every step) though the engine measures only before it frees bins: at a step, and when a clock
    jump starts a stream over."""
    msgs = messages(100, CLOCKS, message_ns=10 * MS)
    stepped, seen = _held(msgs, step_every=64)
    assert stepped.peak_nbytes == max(seen) > stepped.nbytes  # steps freed bins behind the windows
    cut = int(len(msgs) * 0.6)
    jumped, seen = _held(msgs[:cut + 200], jump_from=cut)  # no step: only the jump frees
    assert jumped.status('/far').jumps == 1
    assert jumped.peak_nbytes == max(seen) > jumped.nbytes


@pytest.mark.parametrize('seconds', [1, 3])
def test_a_recording_that_ends_is_decided_live_on_the_windows_its_end_allows_once_its_streams_fall_silent(seconds):
    """Live fits a window once data reach past it by the search's reach, since more may come; when
    every stream has been silent for ``silence_ns`` nothing more came, and the windows the ends allow
    are fitted and decided, as ``finish`` does: a recording too short to lock before is then decided
    as offline, its correction kept while silent."""
    msgs = messages(seconds, CLOCKS)
    live = run_live(msgs)
    _, offline = run_offline(msgs)
    end = msgs[-1][0]
    live.step(end + live.params.silence_ns // 2)  # quiet, not yet silent: waiting for data past the window
    if seconds == 1:
        assert all(live.state(t) is State.ESTIMATING for t in TRUTH)
    live.step(end + live.params.silence_ns + 100 * MS)
    for topic, truth in TRUTH.items():
        off, st = offline[topic], live.status(topic, end + live.params.silence_ns + 100 * MS)
        assert off.accepted, off.reason
        assert st.state is State.LOST and st.message.startswith('silent for'), st.message
        assert st.correction.offset_ns == off.offset_ns  # the same windows, the same decision
        assert abs(off.offset_ns - truth) <= 3 * off.uncertainty_ns
