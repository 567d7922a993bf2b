"""Clock corrections: how a camera's times map onto the reference camera's timeline.

An event stamped ``t`` (int64 ns, on its camera's own timeline) happened at

    t + offset_ns + skew_ppm * 1e-6 * (t - anchor_ns)

on the reference timeline. The reference itself has offset 0 and skew 0. This is the contract of
``evsync estimate --json`` and of every restamping tool.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from evsync_ros.core.density import TIME_LIMIT_NS
from evsync_ros.core.errors import ParameterError, StreamError


@dataclass(frozen=True)
class ClockCorrection:
    """offset (ns) and skew (ppm, about ``anchor_ns``) that take a camera's times to the reference's."""

    offset_ns: int = 0
    skew_ppm: float = 0.0
    anchor_ns: int = 0

    def __post_init__(self) -> None:
        for name in ('offset_ns', 'anchor_ns'):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or abs(int(value)) > TIME_LIMIT_NS:
                raise ParameterError(f'{name} must be an integer number of nanoseconds within 2^62, got {value!r}')
        if (not isinstance(self.skew_ppm, (int, float, np.integer, np.floating)) or isinstance(self.skew_ppm, bool)
                or not math.isfinite(self.skew_ppm) or abs(self.skew_ppm) >= 1e5):
            raise ParameterError(f'skew_ppm must be finite and below 1e5 in size, got {self.skew_ppm!r}')
        object.__setattr__(self, 'offset_ns', int(self.offset_ns))
        object.__setattr__(self, 'anchor_ns', int(self.anchor_ns))
        object.__setattr__(self, 'skew_ppm', float(self.skew_ppm))

    @property
    def is_identity(self) -> bool:
        """No offset and no skew: the times stay as they are."""
        return self.offset_ns == 0 and self.skew_ppm == 0.0

    def apply(self, t: np.ndarray) -> np.ndarray:
        """The corrected times of an int64 ns array (a new array)."""
        t = np.asarray(t, dtype=np.int64)
        out = t + np.int64(self.offset_ns)
        if self.skew_ppm:
            out += np.rint((t - np.int64(self.anchor_ns)).astype(np.float64) * (self.skew_ppm * 1e-6)).astype(np.int64)
        return out

    def apply_one(self, t: int) -> int:
        """The corrected time of one int ns."""
        return int(t) + self.offset_ns + round((int(t) - self.anchor_ns) * (self.skew_ppm * 1e-6))

    def then(self, after: ClockCorrection) -> ClockCorrection:
        """This correction followed by ``after``, as one map: a camera onto the reference camera's
        timeline, then that timeline onto the host's. Anchored where ``after`` is (in this map's
        input times), so that its offset is the one in force there, not one extrapolated to 0."""
        k1, k2 = self.skew_ppm * 1e-6, after.skew_ppm * 1e-6
        anchor = after.anchor_ns - self.offset_ns
        mid = self.apply_one(anchor)
        return ClockCorrection(offset_ns=after.apply_one(mid) - anchor, skew_ppm=(k1 + k2 + k1 * k2) * 1e6,
                               anchor_ns=anchor)

    def inverse(self) -> ClockCorrection:
        """The correction that undoes this one (exact for a pure offset; to within 1 ns with skew)."""
        k = self.skew_ppm * 1e-6
        # u = t + o + k (t - a)  =>  t = u - o' - k' (u - a') with the reference times' anchor a' = a + o.
        return ClockCorrection(offset_ns=-self.offset_ns, skew_ppm=-k / (1 + k) * 1e6,
                               anchor_ns=self.anchor_ns + self.offset_ns)


class CorrectionTrack:
    """A camera's correction as it changed over time: samples of (its own time, the rig's time of the
    same instant), as the node publishes them on /evsync/offsets (``sensor_msgs/TimeReference``),
    joined by straight lines. ``at(t)`` is the line through the two samples around ``t`` (the first
    or last two beyond them; a single sample: its offset). StreamError without a sample."""

    def __init__(self, own_ns: np.ndarray, rig_ns: np.ndarray, *, topic: str) -> None:
        own, rig = np.asarray(own_ns, np.int64), np.asarray(rig_ns, np.int64)
        if own.size == 0 or own.shape != rig.shape:
            raise StreamError(f'{topic}: no samples of its correction')
        order = np.argsort(own, kind='stable')
        own, rig = own[order], rig[order]
        keep = np.ones(own.size, bool)
        keep[1:] = own[1:] != own[:-1]  # one sample per own time (the newest report wins)
        last = np.flatnonzero(keep)
        self.own_ns, self.rig_ns = own[keep], rig[np.r_[last[1:] - 1, own.size - 1]]
        self.topic = topic

    def __len__(self) -> int:
        return int(self.own_ns.size)

    def at(self, t_ns: int) -> ClockCorrection:
        """The correction in force around the camera's time ``t_ns``."""
        own, rig = self.own_ns, self.rig_ns
        if own.size == 1:
            return ClockCorrection(offset_ns=int(rig[0] - own[0]))
        i = int(np.clip(np.searchsorted(own, t_ns, side='right') - 1, 0, own.size - 2))
        slope = (rig[i + 1] - rig[i]) / (own[i + 1] - own[i])
        return ClockCorrection(offset_ns=int(rig[i] - own[i]), skew_ppm=float((slope - 1.0) * 1e6),
                               anchor_ns=int(own[i]))
