"""The text of ``evsync estimate`` and ``evsync report``: the offsets table, each camera's windows, and
what a bag's recorded /evsync/offsets say."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from evsync_ros.core.clock import ClockCorrection, CorrectionTrack
from evsync_ros.core.results import CameraFit, RigFit, WindowFit


def format_seconds(ns: int) -> str:
    """Signed seconds with all nine decimals (offsets can be decades of nanoseconds)."""
    sign = '-' if ns < 0 else '+'
    sec, rem = divmod(abs(int(ns)), 1_000_000_000)
    return f'{sign}{sec}.{rem:09d}'


def _uncertainty(c: Mapping[str, object]) -> str:
    se = c.get('uncertainty_ns')
    return f'{float(se) / 1e6:.3f}' if isinstance(se, (int, float)) else '-'


def offsets_table(rig: RigFit, *, events: Mapping[str, int] | None = None) -> str:
    """The offsets, one line per camera, as the contract's JSON has them; under the table, why each
    camera not accepted is not."""
    doc = rig.as_json()
    head = (f'{"topic":<28} {"events":>10} {"offset s":>22} {"+- ms":>7} {"skew ppm":>9} {"windows":>7} '
            f'{"confidence":>10} accepted')
    lines = [f'reference {doc["reference"]}', head, '-' * len(head)]
    reasons = []
    for c in doc['cameras']:
        n = f'{events[c["topic"]]:,}' if events and c['topic'] in events else '-'
        windows = f'{c["windows_agreeing"]}/{c["windows_total"]}' if 'windows_total' in c else '-'
        if c['topic'] == doc['reference']:
            windows = '-'
        lines.append(f'{c["topic"]:<28} {n:>10} {format_seconds(c["offset_ns"]):>22} {_uncertainty(c):>7} '
                     f'{c["skew_ppm"]:>+9.2f} {windows:>7} {c["confidence"]:>10.3f} '
                     f'{"yes" if c["accepted"] else "NO"}')
        if not c['accepted'] and c.get('reason'):
            reasons.append(f'{c["topic"]}: not accepted, {c["reason"]}')
    if reasons:
        lines += [''] + reasons
    if rig.host is not None:
        h = rig.host
        lines += ['', f'host time: the cameras\' timeline runs {h.skew_ppm:+.2f} ppm against the host clock; arrival '
                  f'lags scatter {h.residual_ns / 1e6:.3f} ms (RMS) about the fitted line over {h.segments} segments '
                  f'({h.dropped} dropped late); the line is known to {h.uncertainty_ns / 1e3:.1f} us, and host times '
                  'are late by the least transport latency, which arrival times cannot show']
    return '\n'.join(lines)


def window_points(cam: CameraFit, fits: Sequence[WindowFit], *, binned: ClockCorrection | None = None
                  ) -> list[tuple[int, int]]:
    """(camera time, offset there) of each window's centre, on the camera's own timeline: what the
    camera's line (``cam.correction``) is drawn against.

    A window's ``offset_ns`` is measured on the timeline its camera's times were binned on: as
    recorded, or through ``binned`` (a second pass bins them with the first pass's skew taken out,
    and its windows' offsets are then constant offsets on that de-skewed timeline). The window's
    centre on the reference, less its offset, is the centre on that timeline; ``binned`` undone
    gives the camera's own time ``c``, and the reference time less ``c`` the offset there. Each
    window is then set against the line once, however it was binned."""
    undo = binned.inverse() if binned is not None and not binned.is_identity else None
    points = []
    for f in fits:
        on_ref = f.ref_start_ns + f.length_ns // 2
        c = on_ref - f.offset_ns
        if undo is not None:
            c = undo.apply_one(c)
        points.append((c, on_ref - c))
    return points


HISTORY_HEAD = f'  {"start s":>10} {"offset - estimate us":>21} {"+- us":>9} {"peak":>6}  window'
"""The columns of each camera's windows: its start after the first window's, its offset less the
camera's line there, the offset's standard error, its correlation peak, how it stands."""


def history_table(cameras: Sequence[CameraFit], windows: Mapping[str, Sequence[WindowFit]], *,
                  binned: Mapping[str, ClockCorrection] | None = None) -> str:
    """Each camera's windows: when, the offset each gave against the final estimate (with its standard
    error), and whether it agrees with the camera's line, one unit per column, named in its header.
    ``binned``: the correction each camera's windows were binned through (``window_points``; absent:
    as recorded)."""
    lines = []
    for cam in cameras:
        fits = windows.get(cam.topic)
        if not fits:
            continue
        t0 = fits[0].ref_start_ns
        spread = '' if cam.spread_ns is None else (
            f' (they spread {cam.spread_ns / 1e3:.1f} us about it, a part of its stated error)')
        lines += [f'{cam.topic}: {len(fits)} windows, {sum(f.accepted for f in fits)} agree with the estimate{spread}',
                  HISTORY_HEAD]
        for f, (c, offset) in zip(fits, window_points(cam, fits, binned=(binned or {}).get(cam.topic))):
            there = cam.correction.apply_one(c) - c
            se = f'{f.se_ns / 1e3:>9.1f}' if f.se_ns != float('inf') else f'{"-":>9}'
            lines.append(f'  {(f.ref_start_ns - t0) / 1e9:>10.2f} {(offset - there) / 1e3:>+21.1f} {se} '
                         f'{f.peak:>6.3f}  {_stands(f)}')
    return '\n'.join(lines)


def _stands(f: WindowFit) -> str:
    """How a window stands against its camera's line."""
    if not f.has_data:
        return 'no data (too little covered)'
    if f.se_ns == float('inf'):
        return 'no clear peak'
    return 'agrees' if f.accepted else 'disagrees'


def provenance_table(record: Mapping[str, object]) -> str:
    """The corrections a restamped bag's provenance says were applied, one line per topic."""
    head = f'{"applied to":<28} {"offset s":>22} {"skew ppm":>9}'
    lines = [head, '-' * len(head)]
    corrections = record.get('corrections')
    for topic, c in (corrections.items() if isinstance(corrections, Mapping) else ()):
        if isinstance(c, Mapping):
            lines.append(f'{topic:<28} {format_seconds(int(c.get("offset_ns", 0))):>22} '
                         f'{float(c.get("skew_ppm", 0.0)):>+9.2f}')
    companions = record.get('companions')
    if isinstance(companions, Mapping) and companions:
        lines.append('companions: ' + ', '.join(f'{t} (with {cam})' for t, cam in companions.items()))
    stamps = record.get('companion_stamps')
    for topic, c in (stamps.items() if isinstance(stamps, Mapping) else ()):
        if isinstance(c, Mapping) and c.get('disagreeing'):
            lines.append(f"warning: companion {topic}: {c['disagreeing']} of {c.get('checked')} stamps disagree with "
                         f"{c.get('camera')}'s event times by more than its packet period "
                         f"({int(c.get('period_ns', 0)) / 1e6:.1f} ms), up to {int(c.get('worst_ns', 0)) / 1e9:+.3f} s "
                         '(libcaer_driver before 1.5.4 stamped IMU and frames so: libcaer_driver#12)')
    return '\n'.join(lines)


def recorded_offsets_table(tracks: Mapping[str, CorrectionTrack], *, topic: str) -> str:
    """What evsync_node published on its offsets topic while a bag was recorded, one line per camera:
    how many corrections, over how long, the offset in force at the first and the last, the skew of a
    line through them all, and the largest change between two corrections in a row (a re-lock, a
    clock step, or the first estimate refined)."""
    head = (f'{"camera":<28} {"samples":>7} {"span s":>8} {"first offset s":>22} {"last offset s":>22} '
            f'{"skew ppm":>9} {"largest step ms":>15}')
    lines = [f'offsets the node published on {topic} while the bag was recorded', head, '-' * len(head)]
    for cam, track in tracks.items():
        own, rig = track.own_ns, track.rig_ns
        offsets = rig - own
        span = int(own[-1] - own[0])
        if own.size > 1 and span > 0:
            slope = np.polyfit((own - own[0]).astype(np.float64), (offsets - offsets[0]).astype(np.float64), 1)[0]
            skew = f'{slope * 1e6:>+9.2f}'
            step = f'{np.abs(np.diff(offsets)).max() / 1e6:>15.3f}'
        else:
            skew, step = f'{"-":>9}', f'{"-":>15}'
        lines.append(f'{cam:<28} {own.size:>7} {span / 1e9:>8.1f} {format_seconds(int(offsets[0])):>22} '
                     f'{format_seconds(int(offsets[-1])):>22} {skew} {step}')
    return '\n'.join(lines)
