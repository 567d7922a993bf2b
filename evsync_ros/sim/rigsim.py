"""A simulated rig at the level of event rates: known offsets for the demo and the core's tests.

numpy only. Model: a shared scene activity a(t) >= 0 (motion episodes with sharp bursts, separated
by still spells, see ``scene_activity``) drives every camera; camera i emits events as an inhomogeneous
Poisson process of rate ``event_rate_hz * a(t) * view_i(t) + noise_rate_hz`` from the world
moment it starts, where view_i is a slow camera-specific modulation (each camera sees the scene
from its own viewpoint). Its clock reads ``clock_at_start_ns + (t_world - start_ns)``.

This is the simulator of the foundation: it has no pixels, so it cannot show the
threshold-dependent lag of a real sensor; the per-pixel rig simulator of the estimation engine
supersedes it for accuracy claims.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from evsync_ros.core.density import TimeArray, check_positive_int
from evsync_ros.errors import ParameterError

_SUB_NS = 50_000  # Poisson sub-bin, 50 us: far below tau and below any offset we resolve


@dataclass(frozen=True)
class SimCamera:
    """One simulated camera."""

    topic: str
    start_ns: int = 0
    """World time at which it starts recording."""
    clock_at_start_ns: int = 0
    """Its clock's reading at that moment (sensor time from 0, or a ROS-time epoch)."""
    event_rate_hz: float = 200_000.0
    """Mean event rate at unit scene activity."""
    noise_rate_hz: float = 2_000.0
    """Background activity, independent of the scene."""


@dataclass(frozen=True)
class SimRig:
    """Cameras watching one scene for ``duration_ns`` of world time (from world time 0)."""

    cameras: tuple[SimCamera, ...]
    duration_ns: int = 30_000_000_000
    seed: int = 0
    reference: str = field(default='')
    """Reference topic; the first camera's when empty."""

    def __post_init__(self) -> None:
        if len(self.cameras) < 2:
            raise ParameterError('a rig needs at least two cameras')
        topics = [c.topic for c in self.cameras]
        if len(set(topics)) != len(topics):
            raise ParameterError(f'camera topics must be distinct, got {topics}')
        check_positive_int(self.duration_ns, name='duration_ns')
        if self.reference and self.reference not in topics:
            raise ParameterError(f'reference {self.reference!r} is not one of {topics}')
        for c in self.cameras:
            if not 0 <= c.start_ns < self.duration_ns:
                raise ParameterError(f'{c.topic}: start_ns must lie in [0, duration_ns)')
            if not (c.event_rate_hz >= 0 and c.noise_rate_hz >= 0):
                raise ParameterError(f'{c.topic}: rates must be non-negative numbers')

    @property
    def reference_topic(self) -> str:
        return self.reference or self.cameras[0].topic

    def true_offsets_ns(self) -> dict[str, int]:
        """Offset of every camera (what to add to its times to reach the reference timeline)."""
        ref = next(c for c in self.cameras if c.topic == self.reference_topic)
        ref_epoch = ref.clock_at_start_ns - ref.start_ns
        return {c.topic: ref_epoch - (c.clock_at_start_ns - c.start_ns) for c in self.cameras}


def default_rig(*, seed: int = 0, duration_ns: int = 30_000_000_000) -> SimRig:
    """The built-in demo rig: three cameras of different makes, clocks and start moments.

    A Prophesee stamped in ROS time is the reference; a DAVIS346 whose clock starts at 0 starts
    1.348 s later (the paper's CeleX example); a DVXplorer started 0.412 s earlier with its
    clock at 5 s.
    """
    return SimRig(
        cameras=(
            SimCamera('/prophesee/events', start_ns=600_000_000, clock_at_start_ns=1_763_700_000_123_456_789,
                      event_rate_hz=300_000.0, noise_rate_hz=3_000.0),
            SimCamera('/davis/events', start_ns=1_948_000_000, clock_at_start_ns=0,
                      event_rate_hz=120_000.0, noise_rate_hz=1_500.0),
            SimCamera('/dvxplorer/events', start_ns=188_000_000, clock_at_start_ns=5_000_000_000,
                      event_rate_hz=180_000.0, noise_rate_hz=4_000.0),
        ),
        duration_ns=duration_ns,
        seed=seed,
    )


def _slow_noise(n_sub: int, knot_ns: float, rng: np.random.Generator) -> np.ndarray:
    """Zero-mean, unit-variance noise that varies on the scale of ``knot_ns`` (linear between knots)."""
    n_knots = int(n_sub * _SUB_NS / knot_ns) + 2
    knots = rng.standard_normal(n_knots)
    return np.interp(np.arange(n_sub) * (_SUB_NS / knot_ns), np.arange(n_knots), knots)


def scene_activity(n_sub: int, rng: np.random.Generator) -> np.ndarray:
    """Shared scene activity per 50 us sub-bin, mean 1.

    Motion episodes of 0.8-3 s (a person raising a hand, a camera sweep) separated by still
    spells of 1-4 s; inside an episode, edges crossing pixels make sharp bursts of 1-20 ms on a
    smooth envelope. Still spells keep a trickle of activity (5 % of an episode's).
    """
    t_ns = np.arange(n_sub, dtype=np.float64) * _SUB_NS
    act = np.full(n_sub, 0.05)
    t = rng.uniform(0.2e9, 1.5e9)
    while t < n_sub * _SUB_NS:
        length = rng.uniform(0.8e9, 3e9)
        lo, hi = int(t // _SUB_NS), min(n_sub, int((t + length) // _SUB_NS))
        tt = t_ns[lo:hi] - t
        ramp = 0.1e9
        envelope = np.clip(np.minimum(tt, length - tt) / ramp, 0.0, 1.0) * rng.uniform(0.5, 1.5)
        bursts = np.full(hi - lo, 0.3)
        for c in rng.uniform(0, length, int(length / 1e9 * 40)):
            w = rng.uniform(1e6, 20e6)
            j0, j1 = int(max(0, c - 4 * w) // _SUB_NS), int(min(length, c + 4 * w) // _SUB_NS)
            bursts[j0:j1] += rng.exponential(1.5) * np.exp(-0.5 * ((tt[j0:j1] - c) / w) ** 2)
        act[lo:hi] += envelope * bursts
        t += length + rng.uniform(1e9, 4e9)
    return act / act.mean()


def simulate_streams(rig: SimRig) -> dict[str, TimeArray]:
    """Event times of every camera, int64 ns on its own clock, sorted."""
    rng = np.random.default_rng(rig.seed)
    n_sub = -(-rig.duration_ns // _SUB_NS)
    act = scene_activity(n_sub, rng)
    out: dict[str, TimeArray] = {}
    for cam in rig.cameras:
        view = np.clip(1.0 + 0.15 * _slow_noise(n_sub, 2e9, rng), 0.3, 3.0)
        lam = (cam.event_rate_hz * act * view + cam.noise_rate_hz) * (_SUB_NS * 1e-9)
        first = cam.start_ns // _SUB_NS
        lam[:first] = 0.0
        counts = rng.poisson(lam)
        sub = np.repeat(np.arange(n_sub, dtype=np.int64), counts)
        world = sub * _SUB_NS + rng.integers(0, _SUB_NS, sub.size, dtype=np.int64)
        world = np.sort(world[world >= cam.start_ns])
        out[cam.topic] = world - cam.start_ns + cam.clock_at_start_ns
    return out


def rig_from_start_delays(
    delays_ns: Sequence[int], *, clocks_ns: Sequence[int] | None = None, duration_ns: int, seed: int
) -> SimRig:
    """A rig of identical cameras that start ``delays_ns`` after world time 0.5 s (for tests)."""
    clocks = list(clocks_ns) if clocks_ns is not None else [0] * len(delays_ns)
    cams = tuple(
        SimCamera(f'/cam{i}/events', start_ns=500_000_000 + int(d), clock_at_start_ns=int(c))
        for i, (d, c) in enumerate(zip(delays_ns, clocks))
    )
    return SimRig(cameras=cams, duration_ns=duration_ns, seed=seed)
