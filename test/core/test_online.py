"""The online core: lock from arrival-time priors, drift, silence, clock jumps and steps, rejection."""

import numpy as np
import pytest

from evsync_ros.core.engine import Engine, EngineParams, State
from evsync_ros.core.engine.methods.refined import fit as online_fit_one
from evsync_ros.core.paper import PaperParams
from evsync_ros.core.refined import RefinedParams
from evsync_ros.core.runner import InThread
from evsync_ros.errors import ParameterError, StreamError
from evsync_ros.runtime.runner import InProcess
from evsync_testing.streams import BASE, bursty, thinned

MS = 1_000_000
S = 1_000_000_000


class Feed:
    """Cameras seeing one scene, sent in 20 ms messages that arrive 1-4 ms after their last event.

    ``clocks[topic](true_ns)`` is that camera's clock; the reference's is the truth itself. The
    arrival clock is the true time (any host clock, as long as it is one for all streams).
    """

    def __init__(self, seconds, clocks, *, seed=3, rate=60.0, message_ns=20 * MS):
        self.truth = bursty(seconds, seed=seed, rate=rate)
        self.rng = np.random.default_rng(seed + 100)
        self.clocks = clocks
        self.message_ns = message_ns
        self.events = {t: thinned(self.truth, 0.5, seed=seed + i) for i, t in enumerate(clocks)}
        self.now = int(self.truth[0])

    def run(self, sync, until_ns, *, silent=(), step_every_ns=500 * MS):
        """Feed every message up to true time ``until_ns`` (except from ``silent`` topics)."""
        next_step = self.now + step_every_ns
        while self.now < until_ns:
            end = self.now + self.message_ns
            for topic, ev in self.events.items():
                part = ev[(ev >= self.now) & (ev < end)]
                if topic in silent or part.size == 0:
                    continue
                receipt = int(part[-1]) + int(self.rng.integers(1 * MS, 4 * MS))
                sync.add(topic, self.clocks[topic](part), receipt)
            self.now = end
            if self.now >= next_step:
                sync.step(self.now)
                next_step += step_every_ns


def offset_clock(offset_ns, skew_ppm=0.0):
    """A camera clock that reads true - offset (so the camera's offset is +offset)."""
    return lambda t: t - offset_ns - np.rint(skew_ppm * 1e-6 * (t - BASE)).astype(np.int64)


def true_offset(topic_clock, cam_time_ns):
    """What must be added to a camera time to get the true (reference) time, by bisection-free inversion."""
    t = cam_time_ns
    for _ in range(3):
        t = t + (cam_time_ns - int(topic_clock(np.array([t]))[0]))
    return t - cam_time_ns


@pytest.mark.parametrize('method, tolerance_ns, early_s', [('refined', 60_000, 0.6), ('paper', 3 * MS, 9)])
def test_locks_to_the_true_offsets(method, tolerance_ns, early_s):
    clocks = {'/ref': lambda t: t, '/b': offset_clock(2_345_678), '/c': offset_clock(-1_000 * S - 123)}
    feed = Feed(30, clocks)
    sync = Engine(clocks, reference='/ref', params=EngineParams(method=method))
    feed.run(sync, feed.now + int(early_s * S))
    # refined: too few windows yet to agree; paper: no whole window of T yet
    assert sync.state('/b') is State.ESTIMATING and sync.correction('/b') is None
    feed.run(sync, feed.now + 29 * S - int(early_s * S))
    for topic, truth in (('/b', 2_345_678), ('/c', -1_000 * S - 123)):
        st = sync.status(topic)
        assert st.state is State.LOCKED, st.message
        assert abs(st.correction.offset_ns - truth) < tolerance_ns
        assert abs(st.prior_ns - truth) < 5 * MS  # the arrival prior: milliseconds
        assert st.windows_accepted >= (3 if method == 'refined' else 1)
        if method == 'refined':
            assert abs(st.correction.offset_ns - truth) <= 3 * st.uncertainty_ns
    assert sync.status('/ref').state is State.LOCKED and sync.correction('/ref').offset_ns == 0


def test_live_windows_never_overlap_and_follow_the_offline_ladder():
    # windows that shared data would agree because of it: every window of a camera's estimate is a
    # whole step of one grid from the reference's start, whatever the camera's prior
    clocks = {'/ref': lambda t: t, '/b': offset_clock(2_345_678), '/c': offset_clock(-1_000 * S - 777)}
    feed = Feed(40, clocks)
    sync = Engine(clocks, reference='/ref')
    lengths: dict[str, set[int]] = {topic: set() for topic in ('/b', '/c')}
    grid = sync._streams['/ref'].grid_ns
    first = int(feed.events['/ref'][0])
    origin = first + (-first) % grid  # the reference's first event, up onto the bins' grid
    while feed.now < int(feed.truth[0]) + 39 * S:
        feed.run(sync, feed.now + 2 * S)
        for topic, seen in lengths.items():
            est = sync._streams[topic].estimate
            if est is None:
                continue
            starts = sorted(w.ref_start_ns for w in est.windows)
            used = {w.length_ns for w in est.windows}
            assert len(used) == 1  # one length at a time
            (length,) = used
            seen.add(length)
            assert all(b - a >= length for a, b in zip(starts, starts[1:]))  # no overlap
            assert all((w - origin) % length == 0 for w in starts)  # on the grid from the reference
    for topic, seen in lengths.items():
        assert min(seen) == RefinedParams().min_window_ns  # starting short ...
        assert max(seen) >= 5 * S  # ... growing with the span
        assert sync.state(topic) is State.LOCKED


def test_each_window_is_fitted_once_as_the_grid_grows():
    # the longer windows once replaced the shorter ones' estimate only when they were also the
    # newest: until then they were dropped and fitted again at every step (a core's fifth, live)
    clocks = {'/ref': lambda t: t, '/b': offset_clock(2_345_678)}
    feed = Feed(34, clocks)
    fitted: list[tuple[int, int]] = []

    class Counting(InThread):
        def run(self, fn, calls):
            if fn is online_fit_one:
                fitted.extend((job.start_ns, job.length_ns) for _, job, _ in calls)
            return super().run(fn, calls)

    sync = Engine(clocks, reference='/ref', runner=Counting())
    feed.run(sync, int(feed.truth[0]) + 33 * S)
    assert len(fitted) == len(set(fitted)), f'{len(fitted) - len(set(fitted))} windows fitted again'
    assert max(length for _, length in fitted) >= 5 * S  # the grid did grow
    assert sync.state('/b') is State.LOCKED


def test_tracks_drift_as_a_skew():
    clocks = {'/ref': lambda t: t, '/b': offset_clock(40 * MS, skew_ppm=30.0)}
    feed = Feed(75, clocks, rate=80.0)
    sync = Engine(clocks, reference='/ref')
    feed.run(sync, feed.now + 74 * S)
    c = sync.correction('/b')
    assert sync.state('/b') is State.LOCKED
    assert c.skew_ppm == pytest.approx(30.0, abs=5.0)
    for cam_time in (int(feed.truth[-1]) - 40 * MS - 5 * S, int(feed.truth[-1]) - 40 * MS - 30 * S):
        assert abs(c.apply_one(cam_time) - cam_time - true_offset(clocks['/b'], cam_time)) < 100_000


def test_a_drifting_clock_gets_its_slope_live_from_the_windows_that_agree():
    clocks = {'/ref': lambda t: t, '/b': offset_clock(40 * MS, skew_ppm=50.0)}
    feed = Feed(30, clocks, rate=80.0)
    sync = Engine(clocks, reference='/ref')
    feed.run(sync, feed.now + 20 * S)
    st = sync.status('/b')
    assert st.state is State.LOCKED, st.message
    assert st.correction.skew_ppm == pytest.approx(50.0, abs=5.0)
    # the messages arriving now are restamped to well within the 1 ms a skew of 0 would leave
    newest = int(clocks['/b'](np.array([feed.now]))[0])
    assert abs(st.correction.apply_one(newest) - newest - true_offset(clocks['/b'], newest)) < 60_000


def test_silence_loses_the_lock_and_the_return_regains_it_without_a_jump():
    clocks = {'/ref': lambda t: t, '/b': offset_clock(5 * MS)}
    feed = Feed(60, clocks)
    sync = Engine(clocks, reference='/ref')
    feed.run(sync, feed.now + 22 * S)
    before = sync.correction('/b')
    assert sync.state('/b') is State.LOCKED
    feed.run(sync, feed.now + 6 * S, silent={'/b'})
    st = sync.status('/b', now_ns=feed.now)
    assert st.state is State.LOST and 'silent' in st.message and st.silent_ns > 5 * S
    kept = sync.correction('/b')  # its clock did not jump: keep correcting (on the windows its end allowed)
    assert kept is not None and abs(kept.offset_ns - before.offset_ns) <= 3 * st.uncertainty_ns
    feed.run(sync, feed.now + 25 * S)
    st = sync.status('/b')
    assert st.state is State.LOCKED and st.jumps == 0
    assert abs(st.correction.offset_ns - 5 * MS) < 60_000


def test_a_clock_jump_restarts_the_camera_and_it_locks_to_the_new_offset():
    jump_at: list[int | None] = [None]

    def restarting(t):  # offset 7 ms, then the camera restarts: its clock reads from zero
        out = t - 7 * MS
        return np.where(t >= jump_at[0], t - jump_at[0] + 1_000_000, out)

    clocks = {'/ref': lambda t: t, '/b': restarting}
    feed = Feed(60, clocks)
    jump_at[0] = feed.now + 25 * S
    sync = Engine(clocks, reference='/ref')
    feed.run(sync, jump_at[0])
    assert abs(sync.correction('/b').offset_ns - 7 * MS) < 60_000
    feed.run(sync, jump_at[0] + 1 * S)
    st = sync.status('/b')
    assert st.jumps == 1 and st.state is State.ESTIMATING and st.correction is None
    assert 'jump' in st.message
    feed.run(sync, jump_at[0] + 25 * S)
    st = sync.status('/b')
    assert st.state is State.LOCKED
    assert abs(st.correction.offset_ns - (jump_at[0] - 1_000_000)) < 60_000


def test_a_jump_of_the_reference_restarts_every_camera():
    jump_at: list[int | None] = [None]
    clocks = {'/ref': lambda t: np.where(t >= jump_at[0], t - 3 * S, t), '/b': offset_clock(5 * MS)}
    feed = Feed(60, clocks)
    jump_at[0] = feed.now + 22 * S
    sync = Engine(clocks, reference='/ref')
    feed.run(sync, jump_at[0] + 1 * S)
    assert sync.status('/ref').jumps == 1
    assert sync.state('/b') is State.ESTIMATING and sync.correction('/b') is None
    feed.run(sync, jump_at[0] + 25 * S)
    assert sync.state('/b') is State.LOCKED
    assert abs(sync.correction('/b').offset_ns - (5 * MS - 3 * S)) < 60_000


def test_a_small_step_is_an_outlier_once_and_a_new_line_when_it_stays():
    step_at: list[int | None] = [None]
    clocks = {'/ref': lambda t: t, '/b': lambda t: np.where(t >= step_at[0], t - 5 * MS - 50 * MS, t - 5 * MS)}
    feed = Feed(70, clocks)
    step_at[0] = feed.now + 30 * S
    sync = Engine(clocks, reference='/ref')
    feed.run(sync, step_at[0] + 38 * S)
    st = sync.status('/b')
    assert st.jumps == 0  # 50 ms is no jump of arrival lag (1 s), but the windows see it
    assert st.state is State.LOCKED and abs(st.correction.offset_ns - 55 * MS) < 60_000


def test_unrelated_streams_are_never_locked():
    clocks = {'/ref': lambda t: t, '/b': offset_clock(0)}
    feed = Feed(40, clocks)
    feed.events['/b'] = bursty(40, seed=99) + (feed.events['/ref'][0] - BASE)  # another scene
    sync = Engine(clocks, reference='/ref')
    feed.run(sync, feed.now + 39 * S)
    st = sync.status('/b')
    assert st.windows_tried >= 4 and st.windows_accepted == 0
    assert st.state is State.ESTIMATING and st.correction is None and 'disagree' in st.message


def test_far_event_times_are_counted_not_binned_and_memory_stays_bounded():
    clocks = {'/ref': lambda t: t, '/b': offset_clock(5 * MS)}
    feed = Feed(200, clocks)
    sync = Engine(clocks, reference='/ref')
    feed.run(sync, feed.now + 90 * S)  # the bins of the drift span and the reach are full
    at_90 = sync.nbytes
    near = feed.now - 5 * MS - 2 * MS
    sync.add('/b', np.array([near, near + 1, near + 2, near + 30 * S, near + 10**15], np.int64), feed.now)
    assert sync.status('/b').far_events == 2 and sync.status('/b').jumps == 0
    peak = 0
    for _ in range(10):
        feed.run(sync, feed.now + 10 * S)
        peak = max(peak, sync.nbytes)
    assert sync.nbytes <= at_90 * 1.25
    assert sum(sync.status(t).bins_bytes for t in clocks) == sync.nbytes
    assert 0 < peak <= sync.bins_ceiling_bytes(500 * MS)
    assert sync.state('/b') is State.LOCKED


class Both:
    """Feeds two trackers the same messages."""

    def __init__(self, *syncs):
        self.syncs = syncs

    def add(self, *args):
        for s in self.syncs:
            s.add(*args)

    def step(self, now):
        for s in self.syncs:
            s.step(now)


def test_known_latencies_are_taken_out_of_what_the_front_end_reads():
    # /b's envelope trails the world by 500 us (a slow photoreceptor), the reference's by 100 us, /c's
    # not at all; their clocks are 7 ms and -3 ms off. The envelopes say 7 ms - 400 us and -3 ms + 100 us.
    d_b, d_c = 7 * MS, -3 * MS
    clocks = {'/ref': lambda t: t, '/b': offset_clock(d_b - 400_000), '/c': offset_clock(d_c + 100_000)}
    feed = Feed(30, clocks)
    plain = Engine(clocks, reference='/ref')
    known = Engine(clocks, reference='/ref', latencies_ns={'/ref': 100_000, '/b': 500_000})
    assert known.latency_delta_ns == {'/ref': 0, '/b': 400_000, '/c': -100_000}
    feed.run(Both(plain, known), feed.now + 29 * S)
    for topic, truth, delta in (('/b', d_b, 400_000), ('/c', d_c, -100_000)):
        raw, fixed = plain.correction(topic), known.correction(topic)
        assert known.state(topic) is State.LOCKED
        assert abs(raw.offset_ns - truth) > 60_000  # the envelopes alone are off by the latency
        assert fixed.offset_ns - raw.offset_ns == delta and fixed.skew_ppm == raw.skew_ppm
        assert abs(fixed.offset_ns - truth) < 60_000
        assert known.status(topic).correction == fixed
    assert known.correction('/ref').offset_ns == 0
    with pytest.raises(StreamError, match='/z'):
        Engine(clocks, reference='/ref', latencies_ns={'/z': 1})
    with pytest.raises(ParameterError, match='latency of /b'):
        Engine(clocks, reference='/ref', latencies_ns={'/b': 400.5})  # type: ignore[dict-item]


def test_messages_that_come_late_are_counted_and_a_jump_is_not():
    sync = Engine(['/ref', '/b'], reference='/ref')
    t = BASE
    for k in range(340):  # 1 ms messages, 2 ms after their events; five held up 80 ms on the way (judged
        late = 80 * MS if k in (320, 321, 322, 330, 335) else 0  # once 100 ms of arrivals make a line)
        sync.add('/b', np.arange(t, t + MS, 10_000, dtype=np.int64), t + 2 * MS + late)
        t += MS
    assert sync.status('/b').late_messages == 5
    for _ in range(2):  # a clock jump (two messages: one alone could be a corrupt time), not lateness
        sync.add('/b', np.arange(t, t + MS, 10_000, dtype=np.int64), t + 2 * MS + 3 * S)
        t += MS
    assert sync.status('/b').late_messages == 5 and sync.status('/b').jumps == 1


def test_parameters_and_topics_are_checked():
    with pytest.raises(ParameterError, match='method'):
        EngineParams(method='fastest')
    with pytest.raises(ParameterError, match='silence_ns'):
        EngineParams(silence_ns=-1)
    with pytest.raises(StreamError, match='reference'):
        Engine(['/a', '/b'], reference='/c')
    with pytest.raises(StreamError, match='at least one'):
        Engine(['/a'], reference='/a')
    sync = Engine(['/a', '/b'], reference='/a', params=EngineParams(
        method='paper', paper=PaperParams(tau_ns=MS), refined=RefinedParams()))
    with pytest.raises(StreamError, match='/z'):
        sync.add('/z', np.zeros(1, np.int64), 0)


# -- operating: saved offsets, freeze, reacquire (issue 24) ------------------------------------------

def _fit(topic, offset_ns, skew_ppm=0.0, anchor_ns=0):
    from evsync_ros.core.results import CameraFit
    return CameraFit(topic=topic, offset_ns=offset_ns, skew_ppm=skew_ppm, anchor_ns=anchor_ns, accepted=True,
                     cost=0.1, confidence=0.9, window_ns=(0, 10 * S), uncertainty_ns=20_000.0)


def test_a_seed_corrects_from_the_first_message_and_locks_when_the_estimate_agrees():
    clocks = {'/ref': lambda t: t, '/b': offset_clock(2_345_678)}
    feed = Feed(30, clocks)
    sync = Engine(clocks, reference='/ref')
    sync.seed(_fit('/b', 2_345_678 + 30_000))  # saved a while ago: 30 us from today's truth
    assert sync.state('/b') is State.SEEDED and sync.correction('/b').offset_ns == 2_375_678
    feed.run(sync, feed.now + 1 * S)
    assert sync.state('/b') is State.SEEDED  # corrected from the start, while the estimate runs
    feed.run(sync, feed.now + 20 * S)
    st = sync.status('/b')
    assert st.state is State.LOCKED and st.seeds_replaced == 0 and 'replaced' not in st.message
    assert abs(st.correction.offset_ns - 2_345_678) < 60_000


def test_a_seed_that_disagrees_is_replaced_and_counted():
    clocks = {'/ref': lambda t: t, '/b': offset_clock(2_345_678)}
    feed = Feed(30, clocks)
    sync = Engine(clocks, reference='/ref')
    sync.seed(_fit('/b', 2_345_678 + 400 * MS))  # another rig's file: 400 ms off, inside the search range
    feed.run(sync, feed.now + 21 * S)
    st = sync.status('/b')
    assert st.state is State.LOCKED and st.seeds_replaced == 1
    assert abs(st.correction.offset_ns - 2_345_678) < 60_000


def test_seed_refuses_a_topic_that_is_not_a_camera_of_the_rig():
    sync = Engine(['/ref', '/b'], reference='/ref')
    for topic in ('/ref', '/nope'):
        with pytest.raises(StreamError, match=topic):
            sync.seed(_fit(topic, 1))


def test_freeze_keeps_every_correction_and_reacquire_estimates_again():
    clocks = {'/ref': lambda t: t, '/b': offset_clock(5 * MS)}
    feed = Feed(60, clocks)
    sync = Engine(clocks, reference='/ref')
    feed.run(sync, feed.now + 20 * S)
    locked = sync.correction('/b')
    tried = sync.status('/b').windows_tried
    sync.freeze(True)
    feed.run(sync, feed.now + 10 * S)
    st = sync.status('/b')
    assert st.frozen and st.windows_tried == tried and sync.correction('/b') == locked
    sync.reacquire()
    st = sync.status('/b')
    assert not st.frozen and st.state is State.ESTIMATING and st.correction is None and 'request' in st.message
    feed.run(sync, feed.now + 12 * S)
    st = sync.status('/b')
    assert st.state is State.LOCKED and abs(st.correction.offset_ns - 5 * MS) < 60_000


def test_saved_is_what_a_seed_takes_back_with_the_latency_delta_once():
    clocks = {'/ref': lambda t: t, '/b': offset_clock(5 * MS)}
    feed = Feed(30, clocks)
    sync = Engine(clocks, reference='/ref', latencies_ns={'/b': 300_000})
    feed.run(sync, feed.now + 20 * S)
    saved = sync.saved()
    assert set(saved) == {'/ref', '/b'} and saved['/ref'].offset_ns == 0
    assert saved['/b'].correction == sync.correction('/b')  # as published: the latency delta in it
    again = Engine(clocks, reference='/ref', latencies_ns={'/b': 300_000})
    again.seed(saved['/b'])
    assert again.correction('/b') == sync.correction('/b')


def test_the_lock_is_free_while_windows_are_fitted_and_agreed():
    # a window's fit and a camera's agreement take tens of ms: the message path's add must not wait
    # for them (it waited for the agreement, inside the lock, for up to 20 ms a step at 4 cameras)
    clocks = {'/ref': lambda t: t, '/b': offset_clock(2_345_678)}
    feed = Feed(12, clocks)
    calls: dict[str, int] = {}

    class Probing(InThread):
        def run(self, fn, calls_):
            if calls_:
                assert sync.lock.acquire(blocking=False), f'{fn.__name__} ran under the lock'
                sync.lock.release()
                calls[fn.__name__] = calls.get(fn.__name__, 0) + len(calls_)
            return super().run(fn, calls_)

    sync = Engine(clocks, reference='/ref', runner=Probing())
    feed.run(sync, int(feed.truth[0]) + 11 * S)
    assert calls.get('fit', 0) > 0 and calls.get('decide', 0) > 0
    assert sync.state('/b') is State.LOCKED


def test_an_estimator_process_locks_on_what_the_thread_does():
    # the node's default (estimator: process): windows and agreements pickled to a worker and back
    clocks = {'/ref': lambda t: t, '/b': offset_clock(2_345_678, 20.0), '/c': offset_clock(-1_000 * S - 123)}
    out = {}
    for name, make in (('thread', InThread), ('process', InProcess)):
        r = make()
        try:
            sync = Engine(clocks, reference='/ref', runner=r)
            feed = Feed(20, clocks)
            feed.run(sync, int(feed.truth[0]) + 19 * S)
            out[name] = {t: (sync.state(t), sync.correction(t), sync.status(t).uncertainty_ns) for t in ('/b', '/c')}
        finally:
            r.close()
    assert out['process'] == out['thread']
    assert all(state is State.LOCKED for state, _, _ in out['process'].values())
