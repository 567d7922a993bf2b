"""A rig on host time (``--reference host``): error against host time after 10 s, 60 s and 10 min.

    ./dev run python bench/host.py [--cameras 4] [--seed 0]

What is measured is the host part of ``--reference host`` (``core/host.py``), on simulated
arrivals: each camera publishes one message a millisecond (the drivers' default), its clock
drifting against the host's by up to 10 or 100 ppm; a message reaches the host after a latency
floor of its own path (0.2 to 2 ms per camera: USB, driver, DDS; not known to anyone) plus an
exponential jitter of mean 0.3, 1 or 4 ms. The cameras' corrections onto one timeline are the
truth plus errors of the size the density estimate has (30 us in offset, 0.05 ppm in skew, per
camera; docs/benchmarks.md), so the density part is not what is measured here.

Three ways, in the same run, each giving every camera a map onto host time:
* ours: every camera through its density correction onto one timeline, that timeline through the
  least arrival lags of all cameras pooled;
* ls: each camera alone, a least-squares line through all its arrival lags (smoothed arrival stamps);
* least: each camera alone, through its own least lags (ours without the other cameras).
For each: ``host``, the worst |estimated - true host time| over cameras and the whole recording;
``apart``, the worst disagreement between two cameras' host times for one instant (what a
multi-camera consumer sees). Milliseconds.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.host import HostEnvelope, fit_host

S = 1_000_000_000
FLOORS_MS = (0.2, 2.0)
DURATIONS_S = (10, 60, 600)
JITTERS_MS = (0.3, 1.0, 4.0)
DRIFTS_PPM = (10.0, 100.0)
WAYS = ('ours', 'ls', 'least')


def run(*, cameras: int, seconds: int, jitter_ms: float, drift_ppm: float, seed: int) -> dict[str, tuple[float, float]]:
    """Per way, (host error, cameras apart) in ms for one simulated rig."""
    rng = np.random.default_rng([seed, seconds, int(jitter_ms * 10), int(drift_ppm)])
    host_epoch = 1_763_700_000 * S
    env = HostEnvelope()
    truth: dict[str, tuple[ClockCorrection, np.ndarray]] = {}
    maps: dict[str, dict[str, ClockCorrection]] = {w: {} for w in WAYS}
    for i in range(cameras):
        topic = f'/cam{i}'
        rate = rng.uniform(-drift_ppm, drift_ppm)
        start = int(rng.uniform(0, 1e6)) * S  # each camera's clock from its own epoch
        to_host = ClockCorrection(offset_ns=host_epoch - start, skew_ppm=(1 / (1 + rate * 1e-6) - 1) * 1e6,
                                  anchor_ns=start)
        t_cam = start + np.arange(0, seconds * S, 1_000_000, dtype=np.int64) + int(rng.integers(0, 1_000_000))
        floor = int(rng.uniform(*FLOORS_MS) * 1e6)
        arrive = to_host.apply(t_cam) + floor + rng.exponential(jitter_ms * 1e6, t_cam.size).astype(np.int64)
        env.add_many(topic, t_cam, arrive)
        truth[topic] = (to_host, t_cam)
        own = HostEnvelope()
        own.add_many(topic, t_cam, arrive)
        maps['least'][topic] = fit_host(own, {topic: ClockCorrection()}).correction
        x = (t_cam - t_cam[0]).astype(np.float64) * 1e-9
        b, a = np.polyfit(x, (arrive - t_cam).astype(np.float64), 1)
        maps['ls'][topic] = ClockCorrection(offset_ns=int(round(a)), skew_ppm=b * 1e-3, anchor_ns=int(t_cam[0]))
    ref_host = truth['/cam0'][0]
    density = {}
    for topic, (to_host, _) in truth.items():
        exact = to_host.then(ref_host.inverse())
        noisy = topic != '/cam0'
        density[topic] = ClockCorrection(offset_ns=exact.offset_ns + noisy * int(rng.normal(0, 30_000)),
                                         skew_ppm=exact.skew_ppm + noisy * rng.normal(0, 0.05),
                                         anchor_ns=exact.anchor_ns)
    fit = fit_host(env, density)
    maps['ours'] = {t: c.then(fit.correction) for t, c in density.items()}
    out = {}
    n = 200
    for way, per in maps.items():
        errors = []
        for topic, (to_host, t_cam) in truth.items():
            probe = t_cam[np.linspace(0, t_cam.size - 1, n).astype(int)]
            errors.append(per[topic].apply(probe) - to_host.apply(probe))  # same instants, index by index
        e = np.array(errors, np.float64)
        out[way] = (float(np.abs(e).max()) / 1e6, float((e.max(axis=0) - e.min(axis=0)).max()) / 1e6)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--cameras', type=int, default=4)
    ap.add_argument('--seed', type=int, default=0)
    args = ap.parse_args(argv)
    print(f'{args.cameras} cameras at 1 kHz messages, each with its own unknown latency floor in '
          f'{FLOORS_MS[0]:g}-{FLOORS_MS[1]:g} ms; ms, host error / cameras apart, for ' + ', '.join(WAYS))
    head = f'{"jitter ms":>9} {"drift ppm":>9} {"seconds":>7} ' + ' '.join(f'{w:>13}' for w in WAYS)
    print(head)
    print('-' * len(head))
    for jitter in JITTERS_MS:
        for drift in DRIFTS_PPM:
            for seconds in DURATIONS_S:
                r = run(cameras=args.cameras, seconds=seconds, jitter_ms=jitter, drift_ppm=drift, seed=args.seed)
                print(f'{jitter:>9g} {drift:>9g} {seconds:>7} '
                      + ' '.join(f'{f"{r[w][0]:.3f}/{r[w][1]:.3f}":>13}' for w in WAYS))
                sys.stdout.flush()
    return 0


if __name__ == '__main__':
    sys.exit(main())
