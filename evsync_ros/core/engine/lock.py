"""The lock state machine: what a camera's corrections follow, decision by decision. Pure; the rule
and its reasons: docs/method.md, "Lock".

- waiting: no event yet. estimating: no accepted decision yet; no correction.
- seeded: a saved correction is in force until the camera's own decision is accepted (then locked,
  the seed kept or replaced and counted).
- locked: the newest decision is accepted, or says only that there is no new evidence (too short,
  too flat: quiet windows are not evidence against a lock); the correction is its line.
- lost: was locked, and the newest decision is not accepted for any other reason (it disagrees, is
  uncertain, ambiguous, could be chance, or the clock stepped); the last correction is kept.
- Hysteresis: lost goes back to locked on an accepted decision whose line agrees with the correction
  kept (within 3 standard errors and the systematic margin), or on two accepted decisions in a row.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import Enum

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.results import CameraFit

__all__ = ['CameraLock', 'State']


class State(str, Enum):
    """Where a camera's estimate stands."""

    WAITING = 'waiting'
    SEEDED = 'seeded'
    """Corrected with a saved offset until its own estimate agrees, or replaces it."""
    ESTIMATING = 'estimating'
    LOCKED = 'locked'
    LOST = 'lost'


@dataclass
class CameraLock:
    """One camera's lock (module notes). ``margin_ns``: the systematic margin a seed or a kept
    correction is compared with, beside 3 standard errors."""

    margin_ns: float
    state: State = State.WAITING
    correction: ClockCorrection | None = None
    locked_on: CameraFit | None = None
    """The accepted decision whose correction is in force (or the seed)."""
    message: str = 'waiting for events'
    note: str = ''
    """What happened that the next message should still say (a clock jump, a step)."""
    seeds_replaced: int = 0
    accepted_before: bool = False
    """The previous decision was accepted (the second of two in a row re-locks a lost camera)."""

    def seed(self, fit: CameraFit) -> None:
        """Correct with a saved estimate until the camera's own decision is accepted."""
        self.correction, self.locked_on = fit.correction, fit
        self.state, self.message = State.SEEDED, 'seeded from saved offsets; estimating'

    def forget(self, state: State, message: str) -> None:
        """Drop the correction (a clock jumped, or re-acquiring on request)."""
        self.correction = self.locked_on = None
        self.accepted_before = False
        self.state, self.message = state, message

    def decide(self, est: CameraFit) -> None:
        """The state after the camera's newest decision ``est``."""
        accepted_before, self.accepted_before = self.accepted_before, est.accepted
        note = f'{self.note}; ' if self.note else ''
        if est.accepted:
            self._accepted(est, accepted_before)
        elif self.state is State.SEEDED:
            self.message = f'seeded from saved offsets; estimating: {est.reason}'
        elif self.state is State.LOCKED and est.kind.no_evidence:
            self.message = f'locked; newest windows: {est.reason}'
        elif self.correction is not None:
            self.state = State.LOST
            self.message = f'{note}not accepted now, keeping the last correction: {est.reason}'
        else:
            self.state = State.ESTIMATING
            self.message = f'{note}estimating: {est.reason}'

    def _accepted(self, est: CameraFit, accepted_before: bool) -> None:
        if self.state is State.SEEDED:
            self.note = self._seed_verdict(est)
        elif self.state is State.LOST and not accepted_before and not self._agrees(est):
            self.message = (f'{self.note + "; " if self.note else ""}accepted again '
                            f'{self._apart(est) / 1e6:+.3f} ms from the correction kept; confirming')
            return
        self.correction, self.locked_on = est.correction, est
        self.state = State.LOCKED
        self.message = f'locked; {self.note}' if self.note else 'locked'
        self.note = ''

    def _apart(self, est: CameraFit) -> float:
        assert self.correction is not None
        at = est.anchor_ns
        return est.correction.apply_one(at) - self.correction.apply_one(at)

    def _agrees(self, est: CameraFit) -> bool:
        return abs(self._apart(est)) <= 3 * (est.uncertainty_ns or 0.0) + self.margin_ns

    def _seed_verdict(self, est: CameraFit) -> str:
        """'' when the seed agrees with the camera's own decision (within 3 standard errors and the
        margin, or 1 ms), else a note that it was replaced (counted)."""
        if abs(self._apart(est)) <= max(3 * (est.uncertainty_ns or 0.0) + self.margin_ns, 1_000_000):
            return ''
        self.seeds_replaced += 1
        return f'the saved offset was {self._apart(est) / 1e6:+.3f} ms off and is replaced'

    def published(self, delta_ns: int) -> ClockCorrection | None:
        """The correction in force with a known latency delta added (None: none in force)."""
        c = self.correction
        return replace(c, offset_ns=c.offset_ns + delta_ns) if c is not None and delta_ns else c
