"""Synthetic event-time streams with known activity, for the estimator tests and benchmarks."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

Times = npt.NDArray[np.int64]

BASE = 1_700_000_000 * 10**9
"""Where the streams start (a ROS time in 2023)."""


def bursty(seconds: float, seed: int, rate: float = 60.0) -> Times:
    """Events of a scene with random bursts of motion: Poisson counts on a 1 ms activity envelope."""
    rng = np.random.default_rng(seed)
    ms = int(seconds * 1000)
    envelope = np.convolve(rng.random(ms) ** 6, np.ones(15) / 15, mode='same')
    n = rng.poisson(envelope * rate)
    t = np.repeat(np.arange(ms, dtype=np.int64) * 1_000_000, n) + rng.integers(0, 1_000_000, n.sum())
    return np.sort(t) + BASE


def thinned(times: Times, keep: float, seed: int) -> Times:
    """A second camera seeing the same activity: its own random subset of the events."""
    return times[np.random.default_rng(seed).random(times.size) < keep]


def jittered(times: Times, keep: float, jitter_ns: float, seed: int) -> Times:
    """A camera whose events scatter around the shared activity by a Gaussian of ``jitter_ns``."""
    rng = np.random.default_rng(seed)
    t = times[rng.random(times.size) < keep]
    return np.sort(t + rng.normal(0, jitter_ns, t.size).astype(np.int64))
