"""What the live node's offsets are worth while the clocks drift: ``online.Engine`` fed a long
drifting recording message by message, as the node feeds it, for several drift spans.

    ./dev run python studies/online_drift.py [--seconds 180] [--seeds 6] [--spans 30 60 120]
                                           [--jobs 2]

The drift preset (same-model cameras whose clocks run tens of ppm fast or slow) is simulated for
``--seconds``; each camera's events are sent in 20 ms messages that arrive 1-4 ms after their last
event, and ``step`` runs every 500 ms, as the node's timer does. No DDS: this measures the
estimate, not the transport (``bench/node.py`` measures the node).

At every step, each locked camera's correction is applied to its newest event, and the error is
where that lands on the reference timeline against the truth: the error of the restamp the node
would publish at that moment. ``drift_span`` is how much of the past the tracked line is fitted
over (``EngineParams.drift_span_ns``): a long span fits the skew better but follows a skew that
changes (temperature) more slowly.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import sys
import time

import numpy as np

from evsync_ros.core import online
from evsync_ros.sim import pixelsim

MS = 1_000_000
S = 1_000_000_000
MESSAGE_NS = 20 * MS
STEP_NS = 500 * MS


def one(job: tuple[int, float, tuple[int, ...]]) -> dict:
    """Per span: (camera, seconds since the start, live error ns, skew error ppm) at each step."""
    seed, seconds, spans = job
    rig = pixelsim.preset('drift', seed=seed, duration_s=seconds)
    events = pixelsim.simulate(rig)
    ref_cam = rig.camera(rig.reference)
    true_skew = {c.topic: pixelsim.skew_against(ref_cam, c) for c in rig.cameras}
    syncs = {span: online.Engine([c.topic for c in rig.cameras], reference=rig.reference,
                              params=online.EngineParams(drift_span_ns=span * S)) for span in spans}
    rng = np.random.default_rng([seed, 5])
    true_t = {c.topic: events[c.topic].true_t for c in rig.cameras}
    clock_t = {c.topic: events[c.topic].t for c in rig.cameras}
    out: dict = {span: [] for span in spans}
    now, next_step = 0, STEP_NS
    while now < rig.scene.duration_ns:
        end = now + MESSAGE_NS
        for cam in rig.cameras:
            tt = true_t[cam.topic]
            lo, hi = np.searchsorted(tt, [now, end])
            if hi > lo:
                receipt = int(tt[hi - 1]) + int(rng.integers(1 * MS, 4 * MS))
                for sync in syncs.values():
                    sync.add(cam.topic, clock_t[cam.topic][lo:hi], receipt)
        now = end
        if now < next_step:
            continue
        next_step += STEP_NS
        for span, sync in syncs.items():
            sync.step(now)
            for cam in rig.cameras:
                if cam.topic == rig.reference or sync.state(cam.topic) is not online.State.LOCKED:
                    continue
                tt = true_t[cam.topic]
                k = int(np.searchsorted(tt, now)) - 1
                if k < 0:
                    continue
                c = sync.correction(cam.topic)
                truth = int(pixelsim.camera_clock(ref_cam, np.array([tt[k]]))[0])
                live = c.apply_one(int(clock_t[cam.topic][k])) - truth
                # the truth's skew on the reference timeline: d(ref clock)/d(cam clock) - 1
                out[span].append((cam.topic, now / S, live, c.skew_ppm - true_skew[cam.topic]))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--seconds', type=float, default=180.0)
    ap.add_argument('--seeds', type=int, default=6)
    ap.add_argument('--spans', type=int, nargs='+', default=[30, 60, 120])
    ap.add_argument('--after', type=float, default=60.0, help='where the two periods of the table meet (s, default 60)')
    ap.add_argument('--jobs', type=int, default=2)
    args = ap.parse_args()
    spans = tuple(args.spans)
    t0 = time.perf_counter()
    with multiprocessing.Pool(args.jobs) as pool:
        parts = pool.map(one, [(s, args.seconds, spans) for s in range(args.seeds)], chunksize=1)
    print(f'drift preset, {args.seeds} recordings of {args.seconds:g} s, 20 ms messages, a step every 500 ms, '
          f'in {time.perf_counter() - t0:.0f} s\n')
    head = (f'{"drift span s":>12} {"period":>13} {"steps":>6} | {"live error rms us":>17} {"p99":>6} {"max":>6} | '
            f'{"skew err rms ppm":>16} {"max":>6}')
    print(head)
    print('-' * len(head))
    for span in spans:
        for label, keep in ((f'lock-{args.after:g} s', lambda t: t < args.after),
                            (f'{args.after:g} s-end', lambda t: t >= args.after)):
            rows = [r for part in parts for r in part[span] if keep(r[1])]
            if not rows:
                print(f'{span:>12} {label:>13} {0:>6} | (not locked)')
                continue
            live = np.abs([r[2] for r in rows]) / 1e3
            skew = np.abs([r[3] for r in rows])
            print(f'{span:>12} {label:>13} {len(rows):>6} | {math.sqrt(float(np.mean(live ** 2))):17.1f} '
                  f'{float(np.percentile(live, 99)):6.1f} {float(live.max()):6.1f} | '
                  f'{math.sqrt(float(np.mean(skew ** 2))):16.2f} {float(skew.max()):6.2f}')
    ends = {span: max(abs(last) for part in parts for last in {r[0]: r[3] for r in part[span]}.values())
            for span in spans if any(part[span] for part in parts)}
    print('\nthe largest skew error at the last step: '
          + ', '.join(f'{v:.2f} ppm (span {k} s)' for k, v in ends.items()))
    print('\nlive error: at each step, each locked camera\'s newest event corrected by the tracked line, against the '
          'truth on the reference timeline; skew err: the line\'s skew against the truth (0 until it is significant).')
    return 0


if __name__ == '__main__':
    sys.exit(main())
