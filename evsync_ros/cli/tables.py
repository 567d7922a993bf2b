"""The text of ``evsync estimate`` and ``evsync report``: the offsets table and each camera's windows."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from evsync_ros.core.results import CameraFit, RigFit, WindowFit


def format_seconds(ns: int) -> str:
    """Signed seconds with all nine decimals (offsets can be decades of nanoseconds)."""
    sign = '-' if ns < 0 else '+'
    sec, rem = divmod(abs(int(ns)), 1_000_000_000)
    return f'{sign}{sec}.{rem:09d}'


def offsets_table(rig: RigFit, *, events: Mapping[str, int] | None = None) -> str:
    """The offsets, one line per camera, as the contract's JSON has them."""
    doc = rig.as_json()
    head = (f'{"topic":<28} {"events":>10} {"offset s":>22} {"skew ppm":>9} {"confidence":>10} '
            f'{"cost":>9} accepted')
    lines = [f'reference {doc["reference"]}', head, '-' * len(head)]
    for c in doc['cameras']:
        n = f'{events[c["topic"]]:,}' if events and c['topic'] in events else '-'
        lines.append(f'{c["topic"]:<28} {n:>10} {format_seconds(c["offset_ns"]):>22} {c["skew_ppm"]:>+9.2f} '
                     f'{c["confidence"]:>10.3f} {c["cost"]:>9.2e} {"yes" if c["accepted"] else "NO"}')
    return '\n'.join(lines)


def history_table(cameras: Sequence[CameraFit], windows: Mapping[str, Sequence[WindowFit]], *,
                  window_ns: int) -> str:
    """Each camera's windows: when, the offset each gave against the final estimate, confidence."""
    lines = []
    for cam in cameras:
        fits = windows.get(cam.topic)
        if not fits:
            continue
        t0 = fits[0].ref_start_ns
        lines.append(f'{cam.topic}: {len(fits)} windows, {sum(f.accepted for f in fits)} accepted; offset of each '
                     'window minus the estimate there (us)')
        for f in fits:
            centre = f.ref_start_ns + window_ns // 2 - f.offset_ns  # camera timeline
            there = cam.correction.apply_one(centre) - centre
            lines.append(f'  {(f.ref_start_ns - t0) / 1e9:>8.1f} s  {(f.offset_ns - there) / 1e3:>+10.1f}  '
                         f'confidence {f.confidence:.3f}  {"accepted" if f.accepted else "rejected"}')
    return '\n'.join(lines)
