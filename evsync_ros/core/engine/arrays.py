"""The array API: event times held in memory, fed to the engine as a recording read whole. numpy only.
With no arrival times, a camera's prior is the first events' difference (cameras started about
together) and its search reaches ``RefinedParams.max_shift_ns`` either side."""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from evsync_ros.core.bins import SortedTimes
from evsync_ros.core.density import TimeArray, as_times
from evsync_ros.core.engine.drivers import passes
from evsync_ros.core.engine.drivers.passes import Feeder, Read
from evsync_ros.core.engine.stream import Known
from evsync_ros.core.errors import StreamError
from evsync_ros.core.paper import PaperEstimate, PaperParams
from evsync_ros.core.refined import RefinedParams
from evsync_ros.core.results import CameraFit, Method, RigFit

__all__ = ['ARRIVING_NS', 'CHUNK_NS', 'arriving', 'estimate_offset', 'estimate_offsets', 'estimate_rig',
           'estimate_times', 'fit_camera', 'pair_residuals', 'paper_rig']

CHUNK_NS = 50_000_000
"""Event time per message an array without arrival times is fed in."""
ARRIVING_NS = 1_000_000
"""Arrival time per message an array with arrival times is fed in: the drivers' packet."""


def _messages(times: TimeArray) -> Iterator[TimeArray]:
    """A sorted array cut into messages of ``CHUNK_NS`` of event time."""
    if times.size == 0:
        return
    key = (times - times[0]) // CHUNK_NS
    cuts = np.flatnonzero(key[1:] != key[:-1]) + 1
    yield from np.split(times, cuts)


def _sorted(streams: Mapping[str, Any]) -> dict[str, TimeArray]:
    out = {}
    for name, t in streams.items():
        arr = as_times(t.times if isinstance(t, SortedTimes) else t, name=name)
        if arr.size == 0:
            raise StreamError(f'stream {name!r}: no events to estimate from')
        out[name] = arr if np.all(arr[1:] >= arr[:-1]) else np.sort(arr)
    return out


def arriving(times: TimeArray, arrivals: np.ndarray) -> Iterator[tuple[TimeArray, int]]:
    """Events in the order they arrived, cut into messages of ``ARRIVING_NS`` of arrival time, each
    with its last arrival: what a host receiving them would have seen."""
    order = np.argsort(arrivals, kind='stable')
    t, a = times[order], np.asarray(arrivals, np.int64)[order]
    key = (a - a[0]) // ARRIVING_NS
    cuts = np.flatnonzero(key[1:] != key[:-1]) + 1
    for part, when in zip(np.split(t, cuts), np.split(a, cuts)):
        yield part, int(when[-1])


def estimate_rig(streams: Mapping[str, Any], *, reference: str, params: RefinedParams = RefinedParams(),
                 consistency: bool = True, priors_ns: Mapping[str, int] | None = None,
                 systematic_ns: Mapping[str, float] | None = None,
                 arrivals_ns: Mapping[str, np.ndarray] | None = None) -> RigFit:
    """Every camera against ``reference`` through the engine (``passes.estimate``); with
    ``consistency``, every other pair of accepted cameras too, as a check (``RigFit.pair_residual_ns``).

    Args:
        streams: each camera's event times (int64 ns, any order).
        reference: the camera whose timeline the others join.
        params: the estimator's parameters.
        consistency: also estimate every pair of accepted cameras against each other.
        priors_ns: per camera, the offset its search is centred on (default: first events).
        systematic_ns: per camera, its own systematic error (a known difference of camera models).
        arrivals_ns: per camera, each event's arrival time on one host clock (as ``streams``' order):
            fed as a host would have received them, so the prior and the clock-jump check are the
            arrival times', as for a bag (every camera's, or none).

    Raises:
        StreamError: the reference is not among the streams, a stream is empty or not times, or
            arrival times are given for some cameras only or do not match their events.
    """
    times, arrivals = _checked(streams, reference=reference, arrivals_ns=arrivals_ns)
    read = _reader(times, arrivals)
    known = {t: Known(systematic_ns=v) for t, v in (systematic_ns or {}).items()}
    found = passes.estimate(read, times, reference=reference, params=params, arrivals=bool(arrivals),
                             in_order=bool(arrivals),
                             priors_ns=priors_ns, known=known)
    ordered = {k: np.sort(v) for k, v in times.items()}
    fits = [found.cameras[t] for t in times if t != reference]
    residuals = pair_residuals(ordered, fits, params=params) if consistency else {}
    return RigFit.of(found.cameras, reference=reference, start_ns=int(times[reference].min()),
                     window_ns=params.window_ns, order=times, pair_residual_ns=residuals)


def _checked(streams: Mapping[str, Any], *, reference: str, arrivals_ns: Mapping[str, np.ndarray] | None
             ) -> tuple[dict[str, TimeArray], dict[str, np.ndarray]]:
    """Each stream's times (sorted, when no arrival times give their order) and arrival times, checked."""
    if reference not in streams:
        raise StreamError(f'reference stream {reference!r} is not among {sorted(streams)}')
    arrivals = dict(arrivals_ns or {})
    if arrivals and (set(arrivals) != set(streams)
                     or any(np.shape(arrivals[k]) != np.shape(np.asarray(streams[k])) for k in streams)):
        raise StreamError(f'arrival times must be given for every stream ({sorted(streams)}), one per event')
    times = _sorted(streams) if not arrivals else {k: as_times(v, name=k) for k, v in streams.items()}
    return times, arrivals


def _reader(times: Mapping[str, TimeArray], arrivals: Mapping[str, np.ndarray]) -> Read:
    """Reads arrays into a feeder as messages: in the order a host had them (arrival times), else
    stream by stream (clocks with nothing in common: no step until the end)."""
    def read(feeder: Feeder, again: bool) -> None:
        topics = [name for name in times if name in feeder.topics]
        if arrivals:
            messages = sorted(((when, name, chunk) for name in topics
                               for chunk, when in arriving(times[name], arrivals[name])), key=lambda m: m[0])
            for when, name, chunk in messages:
                feeder.add(name, chunk, when)
            return
        for name in topics:
            for chunk in _messages(times[name]):
                feeder.add(name, chunk)
    return read


def estimate_offsets(streams: Mapping[str, Any], *, reference: str, params: PaperParams = PaperParams(),
                     arrivals_ns: Mapping[str, np.ndarray] | None = None) -> dict[str, PaperEstimate]:
    """The paper's method on event times held whole: every camera against ``reference`` by the paper's
    loop in the engine (``passes.estimate_paper``), as for a bag; the reference is not in the result.
    ``arrivals_ns``: per camera, each event's arrival time (as ``estimate_rig``'s), else each camera's
    windows start at its first event, as the paper's.

    Raises:
        StreamError: the reference is not among the streams, a stream is empty or not times, or
            arrival times are given for some cameras only or do not match their events.
    """
    return _paper(streams, reference=reference, params=params, arrivals_ns=arrivals_ns)[1].paper()


def paper_rig(streams: Mapping[str, Any], *, reference: str, params: PaperParams = PaperParams(),
              arrivals_ns: Mapping[str, np.ndarray] | None = None) -> RigFit:
    """``estimate_offsets``, each camera's decision in the contract's form as the engine makes it
    (with the checks only a whole recording allows: a clock jump), as ``evsync estimate --method
    paper`` gives it."""
    times, found = _paper(streams, reference=reference, params=params, arrivals_ns=arrivals_ns)
    return RigFit.of(found.cameras, reference=reference, start_ns=int(times[reference].min()),
                     window_ns=params.window_ns, order=times)


def _paper(streams: Mapping[str, Any], *, reference: str, params: PaperParams,
           arrivals_ns: Mapping[str, np.ndarray] | None) -> tuple[dict[str, TimeArray], passes.Found]:
    times, arrivals = _checked(streams, reference=reference, arrivals_ns=arrivals_ns)
    return times, passes.estimate_paper(_reader(times, arrivals), times, reference=reference, params=params,
                                         in_order=bool(arrivals))


def estimate_offset(ref_times: object, cam_times: object, *, params: PaperParams = PaperParams(),
                    ref_name: str = 'reference', cam_name: str = 'camera') -> PaperEstimate:
    """The paper's loop for one camera (``cam_times``) against the reference (``ref_times``): successive
    windows of T from each one's first event until min D < epsilon (``estimate_offsets``)."""
    ref_key = ref_name if ref_name != cam_name else f'{ref_name} (reference)'
    return estimate_offsets({ref_key: ref_times, cam_name: cam_times}, reference=ref_key, params=params)[cam_name]


def fit_camera(ref: TimeArray | SortedTimes, cam: TimeArray, *, topic: str, prior_ns: int | None = None,
               params: RefinedParams = RefinedParams(), systematic_ns: float = 0.0) -> CameraFit:
    """One camera (``cam``, named ``topic``) against the reference ``ref``, both event times (int64 ns)
    on their own timelines: ``estimate_rig`` of the two, with the search centred on ``prior_ns``
    when given."""
    name = 'reference' if topic != 'reference' else 'reference camera'
    rig = estimate_rig({name: ref, topic: cam}, reference=name, params=params, consistency=False,
                       priors_ns=None if prior_ns is None else {topic: prior_ns},
                       systematic_ns={topic: systematic_ns})
    return rig.camera(topic)


def pair_residuals(times: Mapping[str, TimeArray], fits: Sequence[CameraFit], *,
                   params: RefinedParams = RefinedParams()) -> dict[tuple[str, str], int]:
    """The consistency check (``RigFit.pair_residual_ns``): every pair i, j of the accepted cameras
    among ``fits`` (the reference left out), j's corrected times estimated against i's corrected
    times, with no skew fitted (both corrections took theirs out). ``times``: each camera's sorted event
    times (int64 ns) on its own clock. A pair whose estimate is not accepted has no entry."""
    single = replace(params, drift=False)
    accepted = [f for f in fits if f.accepted]
    residuals: dict[tuple[str, str], int] = {}
    for i, fi in enumerate(accepted):
        on_i = np.sort(fi.correction.apply(times[fi.topic]))
        for fj in accepted[i + 1:]:
            # j against i: camera j's times onto camera i's timeline
            pair = fit_camera(on_i, np.sort(fj.correction.apply(times[fj.topic])), topic=fj.topic, prior_ns=0,
                              params=single)
            if pair.accepted:
                residuals[(fi.topic, fj.topic)] = pair.offset_ns
    return residuals


def estimate_times(times: dict[str, np.ndarray], *, reference: str, method: Method | str = Method.REFINED,
                   paper_params: PaperParams = PaperParams(), refined_params: RefinedParams = RefinedParams(),
                   consistency: bool = True, latencies_ns: Mapping[str, int] | None = None,
                   systematic_ns: Mapping[str, float] | None = None,
                   arrivals_ns: Mapping[str, np.ndarray] | None = None) -> RigFit:
    """Either method on event times held whole, its result in the contract's form (a RigFit).

    Args:
        times: each camera's event times (int64 ns).
        reference: the camera whose timeline the others join.
        method: 'refined' or 'paper'.
        consistency: refined: also estimate every pair of accepted cameras (``estimate_rig``).
        latencies_ns: known envelope latencies taken out (``RigFit.with_latencies``), either method.
        systematic_ns: refined: per camera, a systematic error of its own (``model_systematic_ns``).
        arrivals_ns: per camera, each event's arrival time (``bag.estimate.read_event_arrivals``), so that the
            engine decides as it does on the bag (``estimate_rig``, ``paper_rig``).

    Raises:
        StreamError: an unknown method, or a camera with no event.
    """
    method = Method.of(method)
    empty = [t for t, arr in times.items() if arr.size == 0]
    if empty:
        raise StreamError(f'no decodable events on {", ".join(empty)}')
    if method is Method.REFINED:
        rig = estimate_rig(times, reference=reference, params=refined_params, consistency=consistency,
                           systematic_ns=systematic_ns, arrivals_ns=arrivals_ns)
        return rig.with_latencies(latencies_ns) if latencies_ns else rig
    rig = paper_rig(times, reference=reference, params=paper_params, arrivals_ns=arrivals_ns)
    return rig.with_latencies(latencies_ns) if latencies_ns else rig
