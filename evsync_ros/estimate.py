"""Estimating offsets from a recorded rosbag2: event times out of the bag, then either method.

A front end: rosbags (through ``bagio``) and the adapters give each event topic's times on its own
timeline; ``paper`` or ``refined`` estimates; the result has the ``evsync estimate --json`` form:

    {"reference": TOPIC, "cameras": [{"topic", "offset_ns", "skew_ppm", "anchor_ns", "accepted",
                                      "cost", "confidence", "window_ns": [start, end]}]}

An event stamped t on its topic's timeline happened at t + offset_ns + skew_ppm*1e-6*(t - anchor_ns)
on the reference's. Messages that cannot be decoded are counted per topic with the first error,
and odd input the adapters counted is reported with them: nothing is dropped unseen.

Times are held in memory (8 bytes an event); bounded-memory streaming is the bag tools' issue.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from msg_adapters.registry import decoder_for, is_event_type

from .bagio import BagReader
from .errors import BagError, MessageError, StreamError
from .paper import PaperParams, estimate_offsets
from .refined import CameraFit, RefinedParams, RigFit, estimate_rig

METHODS = ('paper', 'refined')


@dataclass
class TopicReport:
    msgtype: str
    messages: int = 0
    events: int = 0
    undecodable: int = 0
    first_error: str = ''
    anomalies: dict[str, int] = field(default_factory=dict)


def read_event_times(bag: str | Path, *, topics: Sequence[str] | None = None
                     ) -> tuple[dict[str, np.ndarray], dict[str, TopicReport]]:
    """Each event topic's event times (sorted int64 ns), and what reading it met."""
    with BagReader(bag) as reader:
        conns = {c.topic: c.msgtype for c in reader.connections}
        if topics:
            unknown = [t for t in topics if t not in conns]
            if unknown:
                raise BagError(f'{bag}: no topic {", ".join(unknown)} (topics: {", ".join(sorted(conns))})')
            wrong = [t for t in topics if not is_event_type(conns[t])]
            if wrong:
                raise BagError(f'{bag}: {", ".join(f"{t} ({conns[t]})" for t in wrong)} not an event message type')
            chosen = list(topics)
        else:
            chosen = sorted(t for t, m in conns.items() if is_event_type(m))
        if not chosen:
            raise BagError(f'{bag}: no event topics (topics: {", ".join(sorted(conns)) or "none"})')
        decoders = {t: decoder_for(conns[t]) for t in chosen}
        reports = {t: TopicReport(conns[t]) for t in chosen}
        parts: dict[str, list[np.ndarray]] = {t: [] for t in chosen}
        for conn, _, raw in reader.messages(chosen):
            rep = reports[conn.topic]
            rep.messages += 1
            try:
                _, events = decoders[conn.topic].decode(raw)
            except MessageError as exc:
                rep.undecodable += 1
                rep.first_error = rep.first_error or str(exc)
                continue
            parts[conn.topic].append(events.t)
    times = {}
    for t in chosen:
        reports[t].anomalies = dict(decoders[t].anomalies)
        arr = np.concatenate(parts[t]) if parts[t] else np.empty(0, np.int64)
        if arr.size and not np.all(arr[1:] >= arr[:-1]):
            arr = np.sort(arr)
        reports[t].events = int(arr.size)
        times[t] = arr
    return times, reports


def estimate_times(times: dict[str, np.ndarray], *, reference: str, method: str = 'refined',
                   paper_params: PaperParams = PaperParams(), refined_params: RefinedParams = RefinedParams(),
                   consistency: bool = True, latencies_ns: Mapping[str, int] | None = None) -> RigFit:
    """Either method, its result in the contract's form (a RigFit); ``latencies_ns`` as in
    ``RigFit.with_latencies`` (either method)."""
    if method not in METHODS:
        raise StreamError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    empty = [t for t, arr in times.items() if arr.size == 0]
    if empty:
        raise StreamError(f'no decodable events on {", ".join(empty)}')
    if method == 'refined':
        rig = estimate_rig(times, reference=reference, params=refined_params, consistency=consistency)
        return rig.with_latencies(latencies_ns) if latencies_ns else rig
    estimates = estimate_offsets(times, reference=reference, params=paper_params)
    t0 = int(times[reference].min())
    cams = [CameraFit(reference, 0, 0.0, 0, True, 0.0, 1.0, (t0, t0 + paper_params.window_ns))]
    for topic in times:
        if topic == reference:
            continue
        est = estimates[topic]
        w = est.window
        # the paper has no confidence; how far min D is below epsilon stands in for it
        confidence = max(0.0, 1.0 - est.cost / paper_params.epsilon) if math.isfinite(est.cost) else 0.0
        cams.append(CameraFit(topic, est.offset_ns, 0.0, 0, est.accepted,
                              est.cost if math.isfinite(est.cost) else 1e300, confidence,
                              (w.ref_start_ns, w.ref_start_ns + paper_params.window_ns)))
    rig = RigFit(reference, tuple(cams))
    return rig.with_latencies(latencies_ns) if latencies_ns else rig
