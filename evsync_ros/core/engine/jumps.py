"""The engine's rules at the end of a recording that need no engine: a camera model's error, and
which clock jumps are a camera's own. numpy only."""

from __future__ import annotations

from dataclasses import replace

from evsync_ros.core.refined import MODEL_SYSTEMATIC_NS
from evsync_ros.core.results import CameraFit, Reason

__all__ = ['MATCH_NS', 'jumped', 'model_systematic', 'unmatched']


def model_systematic(model: str, reference_model: str, *, latency_known: bool) -> float:
    """The systematic error a camera's model adds to its offset: ``MODEL_SYSTEMATIC_NS`` when it is
    not the reference's model and its latency is not known, else 0 (one rule offline and live)."""
    return MODEL_SYSTEMATIC_NS if model != reference_model and not latency_known else 0.0


MATCH_NS = 2_000_000_000
"""Two streams' jumps this close in arrival time, and alike in size, are one jump of the host's clock."""


def unmatched(jumps: list[tuple[int, int, int]], others: list[tuple[int, int, int]], jump_ns: int
               ) -> list[tuple[int, int, int]]:
    """The jumps of ``jumps`` that ``others`` has no jump like (a host's clock steps every stream's lag
    alike: no camera's clock jumped)."""
    return [j for j in jumps if not any(abs(j[0] - o[0]) <= MATCH_NS and abs(j[2] - o[2]) <= jump_ns // 2
                                        for o in others)]


def jumped(cam: CameraFit, *, at_ns: int, by_ns: int, first_ns: int) -> CameraFit:
    """``cam`` not accepted for a clock jump of ``by_ns`` at ``at_ns`` (its timeline; ``first_ns``: its
    first event), its reason saying so."""
    what = (f"its arrival times say its clock jumped by {by_ns / 1e6:+.1f} ms against the reference's about "
            f'{(at_ns - first_ns) / 1e9:.1f} s into its recording')
    reason = (f'clock step: {what}, which no one line holds (estimate the stretches apart)' if cam.accepted
              else f'{cam.reason}; {what}')
    return replace(cam, accepted=False, uncertainty_ns=None, skew_uncertainty_ppm=None, reason=reason,
                   kind=Reason.CLOCK_STEP if cam.accepted else cam.kind)
