"""Fuzzing the estimators' inputs (hypothesis): any event times, any parameters. Outcome: a result, or a
StreamError / ParameterError naming the input; never another exception, never a hang.

Event times include what corrupt messages and clock jumps produce: unsorted, duplicated, years
apart, at the ends of what a ROS time can hold, and streams with one event or none.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from evsync_ros.core.bins import BLOCK_BINS, BinnedStream
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.density import TIME_LIMIT_NS, as_times
from evsync_ros.core.engine import Engine, EngineParams
from evsync_ros.core.engine.arrays import estimate_offsets, estimate_rig
from evsync_ros.core.engine.drivers import Offline
from evsync_ros.core.engine.drivers.passes import Feeder
from evsync_ros.core.paper import PaperParams
from evsync_ros.core.refined import RefinedParams
from evsync_ros.errors import ParameterError, StreamError
from evsync_ros.ros.parameters import NODE_PARAMETERS, node_config, node_defaults
from evsync_testing.fuzz import FUZZ, HEAVY, no_hang

S = 1_000_000_000
ROS_MAX = 2**31 * S - 1
odd_numbers = st.one_of(st.integers(-(2**70), 2**70), st.floats(allow_nan=True, allow_infinity=True),
                        st.booleans(), st.none(), st.text(max_size=5), st.just(0), st.just(-1))


@st.composite
def streams(draw) -> np.ndarray:
    """One camera's event times: plausible (a few seconds of activity), corrupt, or both."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    kind = draw(st.sampled_from(['plausible', 'wild', 'mixed', 'tiny', 'jump']))
    base = draw(st.integers(-ROS_MAX, ROS_MAX - 60 * S))
    if kind == 'tiny':
        return base + rng.integers(0, 3 * S, draw(st.integers(0, 3)))
    n = draw(st.integers(1, 20_000))
    t = base + np.sort(rng.integers(0, draw(st.sampled_from([S, 12 * S, 25 * S])), n))
    if kind == 'wild':
        return rng.integers(-ROS_MAX, ROS_MAX, draw(st.integers(1, 200)))
    if kind == 'mixed':
        bad = rng.random(n) < draw(st.sampled_from([0.0001, 0.01, 0.3]))
        t[bad] = rng.integers(-ROS_MAX, ROS_MAX, int(bad.sum()))
    if kind == 'jump':
        t[n // 2:] += draw(st.integers(-ROS_MAX // 2, ROS_MAX // 2))
    return t


small = RefinedParams(window_ns=2 * S, min_window_ns=S // 2, max_shift_ns=S // 2)
small_paper = PaperParams(window_ns=2 * S)


def test_times_beyond_what_a_ros_time_holds_are_refused_by_name():
    with pytest.raises(StreamError, match="'/cam1'.*ROS time"):
        as_times(np.array([0, TIME_LIMIT_NS + 1]), name='/cam1')


@FUZZ
@given(arr=hnp.arrays(dtype=st.sampled_from([np.int64, np.int32, np.uint64, np.float64, np.bool_, np.int8]),
                      shape=hnp.array_shapes(min_dims=0, max_dims=2, max_side=5)))
def test_any_array_is_taken_as_times_or_refused_by_name(arr):
    try:
        t = as_times(arr, name='/cam')
    except StreamError as exc:
        assert '/cam' in str(exc)
        return
    assert t.dtype == np.int64 and t.ndim == 1


@pytest.mark.parametrize('cls', [RefinedParams, PaperParams, EngineParams])
@FUZZ
@given(data=st.data())
def test_any_parameter_value_is_taken_or_refused_as_a_parameter_error(cls, data):
    names = [f for f in cls.__dataclass_fields__ if f not in ('refined', 'paper')]
    name = data.draw(st.sampled_from(names))
    value = data.draw(odd_numbers)
    try:
        params = cls(**{name: value})
    except ParameterError as exc:
        assert name in str(exc) or 'window_ns' in str(exc) or 'tau_ns' in str(exc), str(exc)
        return
    assert getattr(params, name) == value


@FUZZ
@given(offset=odd_numbers, skew=odd_numbers, anchor=odd_numbers)
def test_any_clock_correction_is_taken_or_refused(offset, skew, anchor):
    try:
        c = ClockCorrection(offset_ns=offset, skew_ppm=skew, anchor_ns=anchor)
    except ParameterError:
        return
    assert math.isfinite(c.skew_ppm)
    c.apply(np.array([0, S], np.int64))


@FUZZ
@given(data=st.data())
def test_any_node_parameter_value_is_taken_or_refused_by_name(data):
    values = dict(node_defaults(), topics=['/a', '/b'], types=['dvs_msgs/msg/EventArray'])
    name = data.draw(st.sampled_from(sorted(NODE_PARAMETERS)))
    values[name] = data.draw(st.one_of(odd_numbers, st.lists(st.text(max_size=8), max_size=3)))
    try:
        node_config(values)
    except ParameterError as exc:
        assert name in str(exc) or 'output' in str(exc) or 'reference' in str(exc), str(exc)


@HEAVY
@given(ref=streams(), cam=streams(), method=st.sampled_from(['refined', 'paper']))
def test_batch_estimates_of_any_times_finish_or_refuse(ref, cam, method):
    with no_hang(30):
        try:
            if method == 'refined':
                fit = estimate_rig({'/ref': ref, '/cam': cam}, reference='/ref', params=small)
                cam_fit = fit.cameras[1]
                assert isinstance(cam_fit.offset_ns, int) and math.isfinite(cam_fit.skew_ppm)
                assert 0 <= cam_fit.confidence <= 1 or math.isnan(cam_fit.confidence)
            else:
                est = estimate_offsets({'/ref': ref, '/cam': cam}, reference='/ref', params=small_paper)['/cam']
                assert isinstance(est.offset_ns, int)
        except StreamError as exc:
            assert '/ref' in str(exc) or '/cam' in str(exc), str(exc)


@HEAVY
@given(ref=streams(), cam=streams(), chunks=st.integers(1, 40), method=st.sampled_from(['refined', 'paper']))
def test_streamed_estimates_of_any_times_finish_or_refuse_in_bounded_memory(ref, cam, chunks, method):
    est = Engine(['/ref', '/cam'], reference='/ref', driver=Offline(),
                 params=EngineParams(method=method, refined=small, paper=small_paper))
    peak = 0
    with no_hang(30):
        for a, b in zip(np.array_split(ref, chunks), np.array_split(cam, chunks)):
            Feeder(est).add('/ref', a)
            Feeder(est).add('/cam', b)
            peak = max(peak, est.nbytes)
        try:
            est.finish()
        except StreamError as exc:
            assert '/ref' in str(exc) or '/cam' in str(exc), str(exc)
    # far-apart times are binned block by block: at most a few blocks per chunk and stream
    assert peak <= 2 * chunks * 8 * BLOCK_BINS * 4


@FUZZ
@given(chunks=st.lists(streams(), min_size=1, max_size=6))
def test_binned_stream_accounts_for_every_event(chunks):
    bins = BinnedStream(grid_ns=50_000)
    with no_hang():
        for c in chunks:
            bins.add(c)
    assert bins.events == sum(c.size for c in chunks)
    if bins.origin_ns is not None:
        bins.flush()
        kept = sum(int(b.sum()) for b in bins._blocks.values())
        assert kept + bins.far_events + bins.dropped_late == bins.events


@FUZZ
@given(data=st.data(), method=st.sampled_from(['refined', 'paper']))
def test_online_sync_takes_any_times_and_arrival_clock(data, method):
    params = EngineParams(method=method, refined=small, paper=small_paper)
    sync = Engine(['/ref', '/cam'], reference='/ref', params=params)
    now = data.draw(st.integers(0, 2**62))
    with no_hang(30):
        for _ in range(data.draw(st.integers(1, 12))):
            topic = data.draw(st.sampled_from(['/ref', '/cam']))
            times = data.draw(streams())
            now += data.draw(st.sampled_from([0, 10**6, S, -S, 40 * S]))
            sync.add(topic, times, now)
            if data.draw(st.booleans()):
                sync.step(now)
        for topic in ('/ref', '/cam'):
            s = sync.status(topic, now_ns=now)
            assert s.state.value in ('waiting', 'estimating', 'locked', 'lost')
