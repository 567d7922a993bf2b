"""What the engine reports of a camera, and the corrections it would save: pure functions of what it
holds. numpy only."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

from evsync_ros.core.engine.lock import State
from evsync_ros.core.engine.placement import prior
from evsync_ros.core.engine.stream import Status
from evsync_ros.core.results import CameraFit, Method

if TYPE_CHECKING:
    from evsync_ros.core.engine.engine import Engine

__all__ = ['saved', 'status']


def status(e: Engine, topic: str, now_ns: int | None) -> Status:
    """What a front end reports of ``topic`` (``now_ns`` on the arrival clock, for its silence)."""
    s = e.stream(topic)
    lock, est = s.lock, s.estimate
    held = lock.locked_on if lock.correction is not None else None
    behind = held if lock.state is State.LOCKED and held is not None else est
    accepted = s.accepted if e.params.method is Method.PAPER else (
        est.windows_agreeing if est is not None and est.accepted else 0)
    return Status(
        topic=topic, state=lock.state, correction=lock.published(e.latency_delta_ns[topic]), prior_ns=prior(e, s),
        cost=est.cost if est is not None else math.nan, confidence=est.confidence if est is not None else math.nan,
        windows_tried=s.tried, windows_accepted=accepted, jumps=s.jumps, events=s.events,
        far_events=s.far_events + s.bins.far_events,
        silent_ns=None if s.last_receipt is None or now_ns is None else now_ns - s.last_receipt,
        window_ns=held.window_ns if held is not None and held.accepted else None, message=lock.message,
        bins_bytes=s.bins.nbytes, uncertainty_ns=held.uncertainty_ns if held is not None else None,
        skew_uncertainty_ppm=held.skew_uncertainty_ppm if held is not None else None,
        reason=behind.reason if behind is not None else '', late_messages=s.late,
        seeds_replaced=lock.seeds_replaced, frozen=e.frozen,
        prior=est.prior if est is not None else None, prior_reason=est.prior_reason if est is not None else '',
        edges=held.edges if held is not None else 0,
        density_offset_ns=held.density_offset_ns if held is not None else None,
        tied_to=held.tied_to if held is not None else '')


def saved(e: Engine) -> dict[str, CameraFit]:
    """The decision in force of each camera that has one (its latency delta included), and the
    reference's entry: what ``results.RigFit`` writes for a later ``Engine.seed``."""
    ref = e.stream(e.reference)
    out = {e.reference: CameraFit.reference_entry(e.reference, start_ns=ref.bins.origin_ns or 0,
                                                  window_ns=e.params.window_ns)}
    for s in e.cameras:
        c, fit = s.lock.correction, s.lock.locked_on
        if c is None:
            continue
        if fit is None or fit.correction != c:  # the paper's lock: a correction, no CameraFit
            fit = CameraFit(topic=s.topic, offset_ns=c.offset_ns, skew_ppm=c.skew_ppm, anchor_ns=c.anchor_ns,
                            accepted=True, cost=math.nan, confidence=math.nan, window_ns=(0, 0))
        out[s.topic] = replace(fit, offset_ns=fit.offset_ns + e.latency_delta_ns[s.topic])
    return out
