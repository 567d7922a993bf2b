"""What the engine needs beyond each method's own parameters. numpy only."""

from __future__ import annotations

from dataclasses import dataclass, replace

from evsync_ros.core.density import check_positive_int
from evsync_ros.core.errors import ParameterError
from evsync_ros.core.paper import PaperParams
from evsync_ros.core.refined import RefinedParams
from evsync_ros.core.results import Method, PriorChoice

__all__ = ['LATENCY_LIMIT_NS', 'LIVE_SEARCH_NS', 'EngineParams']

LATENCY_LIMIT_NS = 1_000_000_000
"""A known envelope latency is a camera's response time: a second or more is a mistake."""
LIVE_SEARCH_NS = 500_000_000
"""The search's half-range around an arrival-time prior (the node's ``search_range_s`` default): a
prior good to milliseconds needs no more, and a narrow search is less often fooled."""


@dataclass(frozen=True)
class EngineParams:
    """What the engine needs beyond the estimators' own parameters."""

    method: Method | str = Method.REFINED
    refined: RefinedParams = RefinedParams(max_shift_ns=LIVE_SEARCH_NS)
    """The refined estimator; its ``max_shift_ns`` is the search half-range around the prior."""
    prior: PriorChoice | str = PriorChoice.AUTO
    """Which prior places the windows (``evidence``): arrival times where they hold, else the events."""
    events_shift_ns: int = RefinedParams().max_shift_ns
    """The search half-range about a camera placed by its events alone (the full range)."""
    paper: PaperParams = PaperParams()
    drift_span_ns: int = 60_000_000_000
    """Live: windows that started within this span of the newest make a camera's decision (the bins of
    this span, and of the search reach, are kept)."""
    silence_ns: int = 2_000_000_000
    """A stream with no message for this long (arrival clock) is silent."""
    jump_ns: int = 1_000_000_000
    """A message whose lag leaves the stream's lag line by more than this is a clock jump."""
    step_ns: int = 10_000_000
    """Windows that depart from the locked line by more than this (and their own errors), agreeing
    among themselves, are a clock step: the estimate starts again from them."""

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, 'method', Method(self.method))
        except ValueError:
            raise ParameterError(f'method must be one of {", ".join(m.value for m in Method)}, '
                                 f'got {self.method!r}') from None
        try:
            object.__setattr__(self, 'prior', PriorChoice(self.prior))
        except ValueError:
            raise ParameterError(f'prior must be one of {", ".join(c.value for c in PriorChoice)}, '
                                 f'got {self.prior!r}') from None
        for name in ('drift_span_ns', 'silence_ns', 'jump_ns', 'step_ns', 'events_shift_ns'):
            check_positive_int(getattr(self, name), name=name)

    @property
    def grid_ns(self) -> int:
        """The bins every stream is counted in."""
        return self.refined.fine_ns if self.method is Method.REFINED else self.paper.tau_ns

    @property
    def window_ns(self) -> int:
        """The longest window."""
        return self.refined.window_ns if self.method is Method.REFINED else self.paper.window_ns

    @property
    def reach_ns(self) -> int:
        """How far beyond the window a camera's counts are read."""
        return self.refined.camera_reach_ns if self.method is Method.REFINED else 0

    def shifted(self, shift_ns: int) -> EngineParams:
        """These parameters with the refined search's half-range ``shift_ns``."""
        if shift_ns == self.refined.max_shift_ns:
            return self
        return replace(self, refined=replace(self.refined, max_shift_ns=shift_ns))
