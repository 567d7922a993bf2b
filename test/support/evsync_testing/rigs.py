"""Simulated recordings for the benchmarks and studies, end to end through a rosbag2 and the adapters."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from evsync_ros.bag import estimate
from evsync_ros.sim import pixelsim, simbag


def recorded(name: str, seed: int, duration: float | None, *, speed_px_s: float | None = None,
             make: dict[str, Any] | None = None
             ) -> tuple[pixelsim.Rig, dict[str, pixelsim.CameraEvents], dict[str, Any], dict[str, np.ndarray]]:
    """(rig, events, ground truth, decoded times) of one preset's recording, through a rosbag2
    (``speed_px_s`` and ``make``: ``pixelsim.preset``'s)."""
    rig = pixelsim.preset(name, seed=seed, duration_s=duration, speed_px_s=speed_px_s, make=make)
    events = pixelsim.simulate(rig)
    work = Path(tempfile.mkdtemp(prefix='evsync-acc-'))
    try:
        truth = simbag.write_rig(rig, events, work / 'bag')
        times, _ = estimate.read_event_times(work / 'bag')
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return rig, events, truth, times
