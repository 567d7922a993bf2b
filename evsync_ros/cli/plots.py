"""The plots of ``evsync report`` and ``evsync demo``: densities, the paper's D(dt), offset over time.

``plot`` imports matplotlib (the ``plot`` extra) when called. It draws from a bag's estimate
(windows, curves, densities) or from the JSON of ``evsync estimate --json`` (the contract: offsets,
skews and their spans only).

The figure has one row per camera against the reference:

1. densities (events per tau over the window's total, as the paper's M(t)) of the most confident
   window, a stretch of ``EXCERPT_NS`` around its busiest second: the reference, the camera before
   alignment (its stamps as recorded when that lies in the searched range, else lined up by first
   events) and after (by the estimate);
2. D(dt), the paper's dissimilarity, over +-``CURVE_NS`` around the estimate (as the paper's
   Fig. 4), with the camera's confidence as the offsets table gives it, and the window's peak
   against its rival;
3. each window's offset against time, relative to the estimate at the anchor, with the fitted
   line when there is drift, accepted and rejected windows marked; a window of a de-skewed pass at
   the offset it stands for on the camera's own timeline (``tables.window_points``), so that each
   is drawn against the line once.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from evsync_ros.cli.tables import window_points
from evsync_ros.core.clock import ClockCorrection, CorrectionTrack
from evsync_ros.core.results import CameraFit, RigFit, WindowFit
from evsync_ros.core.triggers import Verified
from evsync_ros.errors import ParameterError

EXCERPT_NS = 2_000_000_000
CURVE_NS = 50_000_000


def _lag_bins(best: WindowFit, offset_ns: int, tau_ns: int) -> int | None:
    """Index m into the camera counts that pairs reference bin 0 for ``offset_ns`` (None: off range)."""
    s = (best.cam_counts.size - best.ref_counts.size) // 2
    m = s - int(round((offset_ns - best.prior_ns) / tau_ns))
    return m if 0 <= m <= 2 * s else None


def d_curve(best: WindowFit, offset_ns: int, *, tau_ns: int, half_ns: int = CURVE_NS
            ) -> tuple[np.ndarray, np.ndarray]:
    """(dt in ms relative to ``offset_ns``, D) from the window's counts, the paper's eq. 4 per shift."""
    a = best.ref_counts
    n = a.size
    ma = a / max(a.sum(), 1.0)
    centre = _lag_bins(best, offset_ns, tau_ns)
    if centre is None:
        return np.empty(0), np.empty(0)
    k = half_ns // tau_ns
    ms, ds = [], []
    for m in range(max(0, centre - k), min(best.cam_counts.size - n, centre + k) + 1):
        b = best.cam_counts[m:m + n]
        mb = b / max(b.sum(), 1.0)
        ms.append((centre - m) * tau_ns / 1e6)
        ds.append(float(np.sum((ma - mb) ** 2)))
    return np.array(ms), np.array(ds)


def plot(path: str | Path, rig: RigFit, *, windows: Mapping[str, Sequence[WindowFit]] | None = None,
         tau_ns: int = 1_000_000, title: str = '', binned: Mapping[str, ClockCorrection] | None = None) -> Path:
    """Write the figure (module notes) as PNG; from JSON (no windows), the offset lines only.
    ``binned``: the correction each camera's windows were binned through (``tables.window_points``)."""
    plt = _pyplot()
    path = Path(path)
    cams = [c for c in rig.cameras if c.topic != rig.reference]
    cols = 3 if windows else 1
    fig, axes = plt.subplots(max(1, len(cams)), cols, figsize=(5.2 * cols, 3.0 * max(1, len(cams))), squeeze=False)
    for row, cam in zip(axes, cams):
        fits = list((windows or {}).get(cam.topic, ()))
        best = next((f for f in fits if f.ref_counts.size), None)
        if best is not None:
            _densities(row[0], best, cam, rig.reference, tau_ns)
            centre = best.ref_start_ns + best.length_ns // 2 - best.offset_ns
            ms, d = d_curve(best, cam.correction.apply_one(centre) - centre, tau_ns=tau_ns)
            ax = row[1]
            ax.plot(ms, d, color='k', lw=1)
            if d.size:
                ax.axvline(ms[int(np.argmin(d))], color='tab:red', lw=0.8, ls='--')
            # the camera's confidence as the offsets table prints it; the window's own, a quantity of
            # its own, named apart
            ax.set_title(f'D(dt) around the estimate; confidence {cam.confidence:.3f}\n'
                         f"(this window's peak against its rival: {best.confidence:.2f})", fontsize=9)
            ax.set_xlabel('dt - estimate (ms)')
            ax.set_ylabel('D')
        ax = row[-1]
        if fits:
            t0 = fits[0].ref_start_ns
            xs = np.array([(f.ref_start_ns + f.length_ns // 2 - t0) / 1e9 for f in fits])
            points = window_points(cam, fits, binned=(binned or {}).get(cam.topic))
            ys = np.array([(offset - cam.offset_ns) / 1e3 for _, offset in points])
            acc = np.array([f.accepted for f in fits])
            ax.plot(xs[acc], ys[acc], 'o', color='tab:blue', ms=4, label='window agreeing')
            if (~acc).any():
                ax.plot(xs[~acc], ys[~acc], 'x', color='tab:gray', ms=5, label='window disagreeing')
            centres = np.array([c for c, _ in points])
        else:
            start, end = cam.window_ns
            centres = np.linspace(start - cam.offset_ns, end - cam.offset_ns, 20).astype(np.int64)
            t0 = start
            xs = (centres + cam.offset_ns - t0) / 1e9
        line = np.array([(cam.correction.apply_one(int(c)) - int(c) - cam.offset_ns) / 1e3 for c in centres])
        ax.plot(xs, line, '-', color='tab:red', lw=1, label=f'estimate: skew {cam.skew_ppm:+.2f} ppm')
        ax.set_title(f'{cam.topic}: offset over time', fontsize=9)
        ax.set_xlabel('reference time from first window (s)')
        ax.set_ylabel(f'offset - {cam.offset_ns / 1e9:.6f} s (us)')
        ax.legend(fontsize=7)
    return _save(plt, fig, path, title)


def _densities(ax: Any, best: WindowFit, cam: CameraFit, reference: str, tau_ns: int) -> None:
    a = best.ref_counts
    n = a.size
    window = max(1, min(n, EXCERPT_NS // tau_ns))
    busiest = int(np.argmax(np.convolve(a, np.ones(min(n, 1000)), mode='same')))
    lo = max(0, min(n - window, busiest - window // 2))
    t = np.arange(lo, lo + window) * tau_ns / 1e9
    ax.plot(t, a[lo:lo + window] / max(a.sum(), 1.0), color='k', lw=0.8, label=reference)
    after = cam.correction.apply_one(best.ref_start_ns - best.offset_ns) - (best.ref_start_ns - best.offset_ns)
    for offset, label, colour in ((0, 'before (as stamped)', 'tab:gray'), (after, 'after', 'tab:red')):
        m = _lag_bins(best, offset, tau_ns)
        if m is None and label.startswith('before'):
            m, label = _lag_bins(best, best.prior_ns, tau_ns), 'before (first events lined up)'
        if m is None:
            continue
        b = best.cam_counts[m:m + n]
        ax.plot(t, b[lo:lo + window] / max(b.sum(), 1.0), color=colour, lw=0.8, alpha=0.8, label=f'{cam.topic} {label}')
    ax.set_title('densities M(t), most confident window', fontsize=9)
    ax.set_xlabel('s into the window')
    ax.legend(fontsize=7)


def plot_recorded(path: str | Path, tracks: Mapping[str, CorrectionTrack], *, title: str = '') -> Path:
    """Each camera's offset as evsync_node published it on /evsync/offsets while a bag was recorded
    (``restamp.load_offsets_stream``), against the camera's own time from its first sample: one row
    per camera, relative to its first offset."""
    plt = _pyplot()
    path = Path(path)
    fig, axes = plt.subplots(max(1, len(tracks)), 1, figsize=(7.0, 2.6 * max(1, len(tracks))), squeeze=False)
    for (cam, track), (ax,) in zip(tracks.items(), axes):
        offsets = track.rig_ns - track.own_ns
        ax.plot((track.own_ns - track.own_ns[0]) / 1e9, (offsets - offsets[0]) / 1e6, '.-', color='tab:blue',
                ms=3, lw=0.8)
        ax.set_title(f'{cam}: offset published by the node', fontsize=9)
        ax.set_xlabel("camera's own time from its first sample (s)")
        ax.set_ylabel(f'offset - {offsets[0] / 1e9:.6f} s (ms)')
    return _save(plt, fig, path, title)


def plot_verified(path: str | Path, rig: RigFit, results: Sequence[Verified]) -> Path:
    """Each verified camera's agreeing windows: their offset minus the trigger edges' at the window's
    middle, over the recording, with the estimate's error and its stated 3 standard errors."""
    plt = _pyplot()
    shown = [v for v in results if v.window_errors_ns and v.error_ns is not None]
    fig, axes = plt.subplots(max(1, len(shown)), 1, figsize=(7.0, 2.6 * max(1, len(shown))), squeeze=False)
    for v, (ax,) in zip(shown, axes):
        start = rig.camera(rig.reference).window_ns[0]
        x = [(w.ref_start_ns + w.length_ns / 2 - start) / 1e9 for w in rig.camera(v.topic).windows if w.accepted]
        ax.plot(x, [e / 1e3 for e in v.window_errors_ns], 'o', color='tab:blue', ms=4, label='window')
        ax.axhline(v.error_ns / 1e3, color='tab:red', lw=1, label='estimate')  # type: ignore[operator]
        band = 3 * (v.stated_ns or 0) / 1e3
        ax.axhspan(v.error_ns / 1e3 - band, v.error_ns / 1e3 + band, color='tab:red', alpha=0.12)  # type: ignore[operator]
        ax.axhline(0, color='k', lw=0.8)
        ax.set_title(f'{v.topic}: density minus trigger edges', fontsize=9)
        ax.set_xlabel('reference time from the start (s)')
        ax.set_ylabel('error (us)')
        ax.legend(fontsize=7)
    return _save(plt, fig, Path(path), f'verified against {rig.reference}\'s trigger edges')


def _save(plt: Any, fig: Any, path: Path, title: str) -> Path:
    """Title the figure, write it as PNG at ``path``, and free it."""
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (ParameterError naming the extra when it is missing)."""
    try:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise ParameterError('plots need matplotlib: pip install matplotlib (or the evsync_ros[plot] extra)') from exc
    return plt
