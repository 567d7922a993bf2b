"""Estimating offsets from a recorded rosbag2: event times out of the bag, then either method.

A front end: rosbags (through ``bag.reader``) and the adapters give each event topic's times on its own
timeline; ``paper`` or ``refined`` estimates; the result has the ``evsync estimate --json`` form:

    {"reference": TOPIC, "cameras": [{"topic", "offset_ns", "skew_ppm", "anchor_ns", "accepted",
                                      "cost", "confidence", "window_ns": [start, end]}]}

An event stamped t on its topic's timeline happened at t + offset_ns + skew_ppm*1e-6*(t - anchor_ns)
on the reference's. Messages that cannot be decoded are counted per topic with the first error,
and odd input the adapters counted is reported with them: nothing is dropped unseen.

``read_event_times`` holds every event time in memory (8 bytes an event), for small bags, tests and
benchmarks. ``estimate_bag`` streams instead: each message's times are binned as read and freed
once no window needs them (``stream``), so memory follows the estimation window, not the bag.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from evsync_ros.bag import pipeline
from evsync_ros.bag.events import TopicReport, decoded, event_topics, read_ahead
from evsync_ros.bag.reader import BagReader
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine.arrays import pair_residuals
from evsync_ros.core.engine.drivers import passes as reads
from evsync_ros.core.engine.drivers.passes import Feeder
from evsync_ros.core.engine.engine import Engine
from evsync_ros.core.engine.evidence import settled
from evsync_ros.core.engine.jumps import model_systematic
from evsync_ros.core.host import HOST, HostEnvelope, fit_host
from evsync_ros.core.paper import PaperEstimate, PaperParams
from evsync_ros.core.refined import RefinedParams
from evsync_ros.core.results import CameraFit, Method, Prior, PriorChoice, RigFit, WindowFit
from evsync_ros.errors import BagError, StreamError

__all__ = ['BagEstimate', 'TopicReport', 'estimate_bag', 'model_systematic_ns', 'read_event_arrivals',
           'read_event_times']


def read_event_times(bag: str | Path, *, topics: Sequence[str] | None = None, start_s: float | None = None,
                     duration_s: float | None = None) -> tuple[dict[str, np.ndarray], dict[str, TopicReport]]:
    """Each event topic's event times (sorted int64 ns), and what reading it met.

    Holds every event time in memory (16 bytes an event while read): for small bags, tests and benchmarks;
    ``estimate_bag`` streams instead.

    Args:
        bag: a rosbag2 directory, or a single .db3/.mcap file.
        topics: the event topics to read (default: every event topic).
        start_s, duration_s: only the messages recorded in this stretch (seconds from the bag's
            first message; default: all).

    Returns:
        ({topic: times}, {topic: TopicReport}): undecodable messages and decoder anomalies are
        counted in the reports, never dropped unseen.

    Raises:
        BagError: the bag cannot be opened or read, a topic is missing or not an event type.
    """
    times, _, reports = _read_whole(bag, topics=topics, start_s=start_s, duration_s=duration_s)
    for topic, arr in times.items():
        if arr.size and not np.all(arr[1:] >= arr[:-1]):
            times[topic] = np.sort(arr)
    return times, reports


def read_event_arrivals(bag: str | Path, *, topics: Sequence[str] | None = None
                        ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, TopicReport]]:
    """Each event topic's event times in the order the bag holds them, each event's arrival time (its
    message's record time: when the recording host had it), and what reading met: what the array
    API takes to decide as ``estimate_bag`` does (``estimate_times(..., arrivals_ns=...)``). Holds
    16 bytes an event in memory.

    Raises:
        BagError: the bag cannot be opened or read, a topic is missing or not an event type.
    """
    return _read_whole(bag, topics=topics)


def _read_whole(bag: str | Path, *, topics: Sequence[str] | None, start_s: float | None = None,
                duration_s: float | None = None
                ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, TopicReport]]:
    """Each event topic's event times in bag order, each event's record time, and what reading met."""
    with BagReader(bag) as reader:
        chosen = event_topics(reader, bag, topics)
        reports = {t: TopicReport(m) for t, m in chosen.items()}
        parts: dict[str, list[np.ndarray]] = {t: [] for t in chosen}
        when: dict[str, list[np.ndarray]] = {t: [] for t in chosen}
        window = reader.window_ns(start_s, duration_s)
        for topic, chunk, record_ns in decoded(reader, chosen, reports, window=window):
            parts[topic].append(chunk)
            when[topic].append(np.full(chunk.size, record_ns, np.int64))
    empty = np.empty(0, np.int64)
    return ({t: np.concatenate(parts[t]) if parts[t] else empty for t in chosen},
            {t: np.concatenate(when[t]) if when[t] else empty for t in chosen}, reports)


@dataclass
class BagEstimate:
    """What ``estimate_bag`` found: the estimate, what reading met, and what the report plots."""

    rig: RigFit
    reports: dict[str, TopicReport]
    method: Method
    windows: dict[str, list[WindowFit]] = field(default_factory=dict)
    """Refined: each camera's windows (of the final pass), the most confident one with its curve."""
    paper: dict[str, PaperEstimate] = field(default_factory=dict)
    passes: int = 1
    peak_bin_bytes: int = 0
    """Most bytes of binned counts held at once."""
    late_events: dict[str, int] = field(default_factory=dict)
    """Events that came after their bins were freed (too far out of order), per topic."""
    far_events: dict[str, int] = field(default_factory=dict)
    """Events far from the rest of their message (corrupt times), counted and not used, per topic."""
    binned: dict[str, ClockCorrection] = field(default_factory=dict)
    """Refined: per camera whose ``windows`` a second read binned through a skew, that skew (the
    windows' offsets are on that de-skewed timeline: ``cli.tables.window_points``)."""
    timeline: RigFit | None = None
    """With reference ``host``: the cameras on the first one's timeline, before the host map (what
    the windows were measured against)."""


def estimate_bag(bag: str | Path, *, topics: Sequence[str] | None = None, reference: str | None = None,
                 method: Method | str = Method.REFINED, paper_params: PaperParams = PaperParams(),
                 refined_params: RefinedParams = RefinedParams(), latencies_ns: Mapping[str, int] | None = None,
                 host_floor_ns: int = 0, progress: Callable[[int, int], None] | None = None,
                 start_s: float | None = None, duration_s: float | None = None,
                 consistency: bool = False, parallel: bool | None = None,
                 prior: PriorChoice | str = PriorChoice.AUTO) -> BagEstimate:
    """Every event topic's offset (and skew) against a reference, from a rosbag2, with memory
    bounded by the estimation window (docs/bags.md).

    Args:
        bag: a rosbag2 directory, or a single .db3/.mcap file.
        topics: the event topics to use (default: every event topic).
        reference: the reference topic (default: the first of ``topics``, else the first event topic
            by name), or ``host``: every camera onto host time (``core/host.py``; the cameras onto
            the first one's timeline, then that timeline onto when the host had their messages).
        method: 'refined' or 'paper'.
        paper_params, refined_params: each method's parameters.
        latencies_ns: known envelope latencies to take out (``RigFit.with_latencies``).
        host_floor_ns: with reference ``host``, the known least latency from an event to the host
            (taken out; 0: host times are late by it).
        progress: called as ``progress(done, total)`` while messages are read.
        start_s, duration_s: estimate from the messages recorded in this stretch only (seconds
            from the bag's first message; default: the whole bag), since real takes begin and end
            with the rig standing still.
        consistency: refined: also estimate every pair of accepted cameras, the reference left
            out (``refined.pair_residuals``, into ``rig.pair_residual_ns``). Each pair needs both
            cameras' times: the bag's events of the stretch are read once more, into memory.
        prior: what places each camera's windows (``results.PriorChoice``): ``auto``, its record times where
            they behave as one clock's arrivals, else its events alone; ``arrival``; ``events``.
        parallel: refined: whether the messages are read and decoded in a second process while this
            one bins and fits them (the same result either way; ``events.read_ahead``). None: where a
            second core is free and no other thread runs (``pipeline.available``).

    Returns:
        A ``BagEstimate``: the estimate in the contract's form (``rig``), what reading met
        (``reports``, ``late_events``, ``far_events``) and what the report plots (``windows``).

    Raises:
        BagError: the bag cannot be read, a topic is missing or not an event type, or the stretch
            asked for is not in the bag.
        StreamError: a camera has no decodable event, or ``method`` is unknown.

    ``reference`` defaults to the first of ``topics``, else the first event topic by name.
    ``progress(done, total)`` is called as messages are read (total over every pass).
    The refined method is the engine fed from the bag (``engine.offline``: each message's record time
    its arrival time, so every camera is searched where the live node searches it), and reads the
    reference's and those cameras' messages a second time when some camera drifts significantly
    (its times binned with the first pass's skew taken out; docs/bags.md says why that takes a
    read). A camera whose clock jumped against the reference's, as the arrival times tell
    (``host.clock_jumps``), is not accepted, the reason saying so. The paper method stops reading
    once every camera has an accepted window.
    """
    method = Method.of(method)
    choice = PriorChoice(prior)
    with BagReader(bag) as reader:
        chosen = event_topics(reader, bag, topics)
        window = reader.window_ns(start_s, duration_s)
        # reference host: the cameras onto the first one's timeline, then that onto host time
        envelope = HostEnvelope() if reference == HOST else None
        ref = (reference if envelope is None else None) or (topics[0] if topics else next(iter(chosen)))
        if ref not in chosen:
            raise BagError(f'{bag}: reference {ref} is not among the event topics {", ".join(chosen)}')
        # reading and decoding in a second process while this one bins and fits: the refined
        # method's, which reads every message (the paper's loop stops reading once it is done)
        reading = _Reading.of(reader, chosen, window, progress=progress,
                              forked=method is Method.REFINED and pipeline.chosen(parallel))
        reports = {t: TopicReport(m) for t, m in chosen.items()}
        if method is Method.PAPER:
            out, engine = _paper(reading, reports, envelope, ref=ref, paper_params=paper_params, choice=choice)
        else:
            out, engine = _refined(reading, reports, envelope, ref=ref, refined_params=refined_params,
                                   latencies_ns=latencies_ns, choice=choice)
        if progress is not None:
            progress(reading.total, reading.total)
    out.peak_bin_bytes = reading.peak
    if consistency and method is Method.REFINED:  # on the cameras' own estimates, before latencies or host
        times, _ = read_event_times(bag, topics=list(chosen), start_s=start_s, duration_s=duration_s)
        out.rig = replace(out.rig, pair_residual_ns=pair_residuals(times, out.rig.cameras[1:],
                                                                   params=refined_params))
    held = _arrivals_held(out.rig, engine)  # on the cameras' own estimates, before latencies
    if latencies_ns:
        out.rig = out.rig.with_latencies(latencies_ns)
    if envelope is not None:
        out.timeline = out.rig
        out.rig = _on_host(out.rig, envelope, held, host_floor_ns)
    return out


@dataclass
class _Reading:
    """An estimate's reads of a bag (``estimate_bag``): its event topics and stretch, in this process
    or ahead in a forked one (``forked``), the progress over every pass and the most bytes of bins
    held."""

    reader: BagReader
    chosen: dict[str, str]
    window: tuple[int, int] | None
    counts: dict[str, int]
    total: int
    """The messages of every pass so far (a stretch's: its share of the bag's span)."""
    per_message: float
    """Progress a message of the bag counts for (below 1 for a stretch)."""
    forked: bool
    progress: Callable[[int, int], None] | None
    done: int = 0
    peak: int = 0

    @classmethod
    def of(cls, reader: BagReader, chosen: dict[str, str], window: tuple[int, int] | None, *,
           progress: Callable[[int, int], None] | None, forked: bool) -> _Reading:
        counts = reader.message_counts()
        total = sum(counts.get(t, 0) for t in chosen)
        if window is not None:  # the messages of the stretch, about: the progress total
            total = round(total * min(1.0, (window[1] - window[0]) / max(reader.span_ns, 1)))
        per_message = total / max(sum(counts.get(t, 0) for t in chosen), 1)
        return cls(reader, chosen, window, counts, total, per_message, forked, progress)

    def tick(self, n: int) -> None:
        before = self.done
        self.done += n
        if self.progress is not None and self.done // 256 > before // 256:
            self.progress(self.done, self.total)

    def run(self, feeder: Feeder, reports: dict[str, TopicReport], envelope: HostEnvelope | None = None,
            topics: Mapping[str, str] | None = None) -> None:
        """One pass over ``topics`` (default: every event topic chosen) into ``feeder``; what a whole
        pass passed over refused (``BagReader.check_whole``)."""
        topics = self.chosen if topics is None else topics

        def feed(topic: str, t: np.ndarray, record_ns: int, lo: int | None = None, hi: int | None = None) -> None:
            feeder.add(topic, t, record_ns, model=reports[topic].model, lo=lo, hi=hi)

        whole = self.window is None
        if self.forked:
            read_ahead(self.reader, feed, reports, envelope, topics, window=self.window, tick=self.tick)
        else:
            chunks = decoded(self.reader, topics, reports, self.tick, envelope, self.window)
            for message in chunks:
                feed(*message)
                if feeder.done:  # the paper's loop has ended for every camera
                    chunks.close()  # counts what the decoders met so far into the reports
                    whole = False
                    break
        if whole:
            self.reader.check_whole({t: reports[t].messages for t in topics})
        self.peak = max(self.peak, feeder.peak_nbytes)

    def again(self, feeder: Feeder) -> None:
        """A second pass: its own reports (the first pass's stand), no host envelope, and only the
        topics it bins again (the reference and the skewed cameras), counted into the progress."""
        topics = {t: self.chosen[t] for t in feeder.topics}
        self.total += round(self.per_message * sum(self.counts.get(t, 0) for t in topics))
        self.run(feeder, {t: TopicReport(m) for t, m in topics.items()}, topics=topics)


def _paper(reading: _Reading, reports: dict[str, TopicReport], envelope: HostEnvelope | None, *, ref: str,
           paper_params: PaperParams, choice: PriorChoice) -> tuple[BagEstimate, Engine]:
    """The paper's method over ``reading``'s bag (``passes.estimate_paper``)."""
    chosen = reading.chosen

    def read_paper(feeder: Feeder, again: bool) -> None:
        reading.run(feeder, reports, envelope)
        _check_events(reports)  # what the decoders met, before the engine finds a stream empty

    found = reads.estimate_paper(read_paper, chosen, reference=ref, params=paper_params, prior=choice)
    engine = found.engine
    rig = RigFit.of(found.cameras, reference=ref, start_ns=(engine.first_last(ref) or (0, 0))[0],
                    window_ns=paper_params.window_ns, order=chosen)
    return BagEstimate(rig, reports, Method.PAPER, paper=found.paper(), late_events=engine.late_events,
                       far_events=engine.far_events), engine


def _refined(reading: _Reading, reports: dict[str, TopicReport], envelope: HostEnvelope | None, *, ref: str,
             refined_params: RefinedParams, latencies_ns: Mapping[str, int] | None, choice: PriorChoice
             ) -> tuple[BagEstimate, Engine]:
    """The refined method over ``reading``'s bag (``passes.estimate``), a second pass where it asks."""
    chosen = reading.chosen

    def read(feeder: Feeder, again: bool) -> None:
        if again:
            reading.again(feeder)
        else:
            reading.run(feeder, reports, envelope)
            _check_events(reports)  # what the decoders met, before the engine finds a stream empty

    found = reads.estimate(read, chosen, reference=ref, params=refined_params, latencies_ns=latencies_ns,
                             prior=choice)
    passes, cameras, engine = found.passes, found.cameras, found.engine
    rig = RigFit.of(cameras, reference=ref, start_ns=(engine.first_last(ref) or (0, 0))[0],
                    window_ns=refined_params.window_ns, order=chosen)
    return BagEstimate(rig, reports, Method.REFINED, windows={t: list(c.windows) for t, c in cameras.items()},
                       binned=found.binned, passes=passes, late_events=engine.late_events,
                       far_events=engine.far_events), engine


def _arrivals_held(rig: RigFit, engine: Engine) -> set[str]:
    """The cameras of ``rig`` whose record times are one host's arrivals (``evidence.settled``: placed by
    them, accepted, and within ``AGREE_NS`` of where they put it), the reference among them."""
    held = {rig.reference}
    for c in rig.cameras:
        span = engine.first_last(c.topic)
        if c.prior is Prior.ARRIVAL and span is not None and settled(c, engine.arrival_prior(c.topic), span[1]):
            held.add(c.topic)
    return held


def _on_host(rig: RigFit, envelope: HostEnvelope, held: set[str], floor_ns: int) -> RigFit:
    """``rig`` on host time (``host.fit_host``) through its accepted cameras of ``held``, those whose record
    times are one host's arrivals (a bag merged from two hosts, or converted, has none to give); another
    accepted camera is refused on host time, the reason naming its prior."""
    out = rig.on_host(fit_host(envelope, {c.topic: c.correction for c in rig.cameras if c.accepted and c.topic in held},
                               floor_ns=floor_ns))
    cams = [c if c.topic in held or not c.accepted else replace(
        c, accepted=False, uncertainty_ns=None, skew_uncertainty_ppm=None,
        reason=f"not on host time: its record times are not one host's arrivals (prior {_prior_name(c)}"
               f'{": " + c.prior_reason if c.prior_reason else ""})') for c in out.cameras]
    return replace(out, cameras=tuple(cams))


def _prior_name(c: CameraFit) -> str:
    return c.prior.value if c.prior is not None else 'none'


def model_systematic_ns(reports: Mapping[str, TopicReport], *, reference: str,
                        latencies_ns: Mapping[str, int] | None = None) -> dict[str, float]:
    """Per topic, the systematic error a difference of camera models adds to its offset
    (``engine.jumps.model_systematic``, the rule the engine applies offline and live)."""
    known_latency = set(latencies_ns or ())
    ref_model = reports[reference].model
    return {t: model_systematic(r.model, ref_model, latency_known=t in known_latency) for t, r in reports.items()}


def _check_events(reports: Mapping[str, TopicReport]) -> None:
    empty = [t for t, r in reports.items() if r.events == 0]
    if empty:
        detail = '; '.join(f'{t}: {r.messages} messages, {r.undecodable} undecodable'
                           + (f' (first: {r.first_error})' if r.first_error else '') for t, r in reports.items()
                           if t in empty)
        raise StreamError(f'no decodable events on {", ".join(empty)} ({detail})')

