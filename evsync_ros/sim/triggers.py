"""Trigger-in for simulated cameras: one pulse train at true times, wired to every camera, each
camera stamping the edges on its own clock. numpy only; the model and its numbers: docs/simulator.md."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from evsync_ros.errors import ParameterError

NS = 1_000_000_000
RISING, FALLING = 1, 0


@dataclass(frozen=True)
class TriggerTrain:
    """A square pulse train at true (world) times, wired to the trigger input of every camera."""

    hz: float = 1.0
    duty: float = 0.1
    """The fraction of each period the pulse is high: at 1 Hz, 100 ms, a GNSS receiver's PPS pulse."""
    phase_ns: int = 100_000_000
    """True time of the first rising edge."""
    jitter_ns: int = 1_000
    """How far a camera's stamp of an edge may be from its true time: uniform in +-jitter_ns, drawn
    for each camera and edge apart."""
    miss_rate: float = 0.01
    """The chance that a camera misses an edge, for each camera and edge apart."""
    channel: int = 0
    """The trigger channel id every camera records the pulse on (evt3: 0-15)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.hz) and self.hz > 0) or not 0 < self.duty < 1:
            raise ParameterError(f'trigger train: need a rate > 0 Hz and a duty within (0, 1), got {self.hz} Hz, '
                                 f'duty {self.duty}')
        if self.jitter_ns < 0 or not 0 <= self.miss_rate < 1 or not 0 <= self.channel <= 15 or self.phase_ns < 0:
            raise ParameterError(f'trigger train: jitter_ns >= 0, miss_rate within [0, 1), channel 0-15 and '
                                 f'phase_ns >= 0, got {self.jitter_ns}, {self.miss_rate}, {self.channel}, '
                                 f'{self.phase_ns}')
        shortest = min(self.duty, 1 - self.duty) * NS / self.hz
        if shortest <= 2 * self.jitter_ns:
            raise ParameterError(f'trigger train: the pulse ({shortest / 1e6:g} ms high or low at {self.hz:g} Hz) '
                                 f'must outlast twice the jitter ({self.jitter_ns} ns), or edges swap')


def train_edges(train: TriggerTrain, duration_ns: int) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.uint8]]:
    """The train's edges within [0, ``duration_ns``): true times (int64 ns, rising then falling, in
    order) and values (1 rising, 0 falling)."""
    period = NS / train.hz
    n = max(0, math.ceil((duration_ns - train.phase_ns) / period))
    rise = train.phase_ns + np.arange(n) * period
    t = np.rint(np.stack([rise, rise + train.duty * period], axis=1).ravel()).astype(np.int64)
    value = np.tile(np.array([RISING, FALLING], np.uint8), n)
    keep = t < duration_ns
    return t[keep], value[keep]


@dataclass(frozen=True)
class TriggerStamps:
    """What one camera's trigger input recorded of the train."""

    index: npt.NDArray[np.intp]
    """Which edges of the train (indices into ``train_edges``) it recorded, in order."""
    t: npt.NDArray[np.int64]
    """Their stamps on the camera's clock (int64 ns): the clock at the true time plus the jitter."""
    true_t: npt.NDArray[np.int64]
    """Their true times (ns)."""
    value: npt.NDArray[np.uint8]
    channel: int
    missed: npt.NDArray[np.intp]
    """The edges within its recording that it missed."""


def stamp_edges(train: TriggerTrain, true_ns: npt.NDArray[np.int64], value: npt.NDArray[np.uint8], *,
                from_ns: float, clock: Callable[[npt.NDArray[np.int64]], npt.NDArray[np.int64]],
                rng: np.random.Generator) -> TriggerStamps:
    """A camera's record of the edges at ``true_ns`` from true time ``from_ns`` on (its recording),
    ``clock`` mapping true times to its clock readings; jitter and misses drawn from ``rng``."""
    inside = np.flatnonzero(true_ns >= from_ns)
    jitter = rng.integers(-train.jitter_ns, train.jitter_ns + 1, inside.size)
    missed = rng.random(inside.size) < train.miss_rate
    kept = inside[~missed]
    return TriggerStamps(kept, clock(true_ns[kept] + jitter[~missed]), true_ns[kept], value[kept], train.channel,
                         inside[missed])
