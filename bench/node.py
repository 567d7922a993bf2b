"""Live node throughput: sustained events/s with no message lost, the node's CPU, and the latency from
receipt to republish, for 4 cameras, evt3 and dvs, against a naive node in the same run.

    ./dev run python bench/node.py [--seconds 8] [--evt3-rates 5 10 20] [--dvs-rates 1 2 4]

Three processes per run, over Fast DDS on loopback with reliable QoS (depth 2000 everywhere):

* a publisher sending 4 cameras' messages (10 ms of events each, one shared activity, clocks
  seconds apart) at the aggregate rate asked for; every message's frame_id carries its send time
  (CLOCK_MONOTONIC, one clock for every process of this host);
* the node under test: ``evsync_node`` (raw messages, window 2 s so that it locks within the run,
  before_lock forward), or ``naive``: typed subscriptions and publishers, the message as Python
  objects, restamped field by field with a fixed correction and no estimation at all;
* a receiver of the four outputs: messages per topic, and the end-to-end latency of each
  (publisher send to receiver arrival: two DDS hops plus the node).

A run is lossless when every message sent came out. The node's own latency (receipt to publish
return) is what it reports in /diagnostics (latency_p50_us, latency_p99_us); its CPU is its
process's user + system time over the run. Messages are built before the clock starts.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import random
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from evsync_ros.testing.measure import DiagnosticsListener, cpu_seconds

TOPICS = [f'/bench{i}/events' for i in range(4)]
TYPES = {'evt3': 'event_camera_msgs/msg/EventPacket', 'dvs': 'dvs_msgs/msg/EventArray'}
MESSAGE_NS = 10_000_000
S = 1_000_000_000
HOST_EPOCH = 1_763_700_000 * S
FRAME_DIGITS = 19


# --- the publisher ---------------------------------------------------------------------------------

def build_messages(encoding: str, rate: float, seconds: float, seed: int = 0) -> list[tuple[int, int, bytearray]]:
    """(send offset ns, camera, serialized message) in send order: 4 cameras seeing one activity."""
    from msg_adapters.event_array import encode_event_array
    from msg_adapters.event_packet import encode_event_packet
    from msg_adapters.evt3 import encode_evt3
    rng = np.random.default_rng(seed)
    ms = int(seconds * 1000)
    envelope = np.convolve(rng.random(ms) ** 4, np.ones(20) / 20, mode='same')
    envelope /= envelope.mean()
    per_ms = rate / 4 / 1000 * envelope
    frame = '0' * FRAME_DIGITS
    out = []
    for cam in range(4):
        clock_offset = (cam * 7_300_000_123) % (40 * S) + 123_456  # each camera's clock: seconds apart
        n = rng.poisson(per_ms)
        t = np.repeat(np.arange(ms, dtype=np.int64) * 1_000_000, n) + rng.integers(0, 1_000_000, int(n.sum()))
        t.sort()
        x, y = rng.integers(0, 640, t.size), rng.integers(0, 480, t.size)
        p = rng.integers(0, 2, t.size)
        cuts = np.searchsorted(t, np.arange(0, ms * 1_000_000 + 1, MESSAGE_NS))
        for k, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
            if b <= a:
                continue
            send = (k + 1) * MESSAGE_NS
            cam_t = t[a:b] + clock_offset
            if encoding == 'evt3':
                raw = encode_event_packet(stamp_ns=HOST_EPOCH + int(t[a]) + 300_000, frame_id=frame, width=640,
                                          height=480, seq=k + 1, time_base=0, encoding='evt3',
                                          payload=encode_evt3(cam_t // 1000, x[a:b], y[a:b], p[a:b]))
            else:
                raw = encode_event_array(stamp_ns=int(cam_t[0]), frame_id=frame, width=640, height=480,
                                         t=cam_t, x=x[a:b], y=y[a:b], p=p[a:b])
            out.append((send, cam, bytearray(raw)))
    out.sort(key=lambda m: (m[0], m[1]))
    return out


def publisher(encoding: str, rate: float, seconds: float) -> None:
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from evsync_ros.ros.messages import message_class
    messages = build_messages(encoding, rate, seconds)
    rclpy.init()
    node = rclpy.create_node('bench_publisher')
    qos = QoSProfile(depth=2000, reliability=ReliabilityPolicy.RELIABLE)
    pubs = [node.create_publisher(message_class(TYPES[encoding]), t, qos) for t in TOPICS]
    while any(p.get_subscription_count() < 1 for p in pubs):
        time.sleep(0.05)
    time.sleep(1.0)
    print('sending', flush=True)
    start = time.monotonic_ns()
    late = 0
    for send, cam, raw in messages:
        delay = start + send - time.monotonic_ns()
        if delay > 0:
            time.sleep(delay / 1e9)
        elif delay < -MESSAGE_NS:
            late += 1
        raw[16:16 + FRAME_DIGITS] = str(time.monotonic_ns()).rjust(FRAME_DIGITS, '0').encode()
        pubs[cam].publish(bytes(raw))
    elapsed = (time.monotonic_ns() - start) / 1e9
    time.sleep(1.0)
    counts = [0] * 4
    for _, cam, _raw in messages:
        counts[cam] += 1
    print(json.dumps({'sent': counts, 'elapsed_s': elapsed, 'late_messages': late,
                      'bytes': sum(len(m[2]) for m in messages)}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


# --- the receiver ----------------------------------------------------------------------------------

def receiver(encoding: str, seconds: float, suffix: str) -> None:
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from evsync_ros.ros.messages import message_class
    rclpy.init()
    node = rclpy.create_node('bench_receiver')
    qos = QoSProfile(depth=2000, reliability=ReliabilityPolicy.RELIABLE)
    counts = [0] * 4
    latencies: list[int] = []

    def on(cam: int, raw: bytes) -> None:
        now = time.monotonic_ns()
        counts[cam] += 1
        latencies.append(now - int(raw[16:16 + FRAME_DIGITS]))

    for i, t in enumerate(TOPICS):
        node.create_subscription(message_class(TYPES[encoding]), t + suffix, functools.partial(on, i), qos, raw=True)
    print('ready', flush=True)
    deadline = None
    while deadline is None or time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
        if deadline is None and any(counts):
            deadline = time.monotonic() + seconds + 4.0
    lat = np.array(latencies) / 1e6
    print(json.dumps({'received': counts, 'e2e_p50_ms': float(np.percentile(lat, 50)),
                      'e2e_p99_ms': float(np.percentile(lat, 99))}))
    node.destroy_node()
    rclpy.shutdown()


# --- the naive node --------------------------------------------------------------------------------

def naive(encoding: str) -> None:
    """Typed subscriptions, Python objects, a fixed correction applied field by field."""
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from evsync_ros.ros.messages import message_class
    rclpy.init()
    node = rclpy.create_node('bench_naive')
    qos = QoSProfile(depth=2000, reliability=ReliabilityPolicy.RELIABLE)
    cls = message_class(TYPES[encoding])
    offset = 1_234_567

    def shift(stamp) -> None:
        ns = stamp.sec * S + stamp.nanosec + offset
        stamp.sec, stamp.nanosec = divmod(ns, S)

    def on(pub, msg) -> None:
        shift(msg.header.stamp)
        if encoding == 'dvs':
            for e in msg.events:
                shift(e.ts)
        pub.publish(msg)

    for t in TOPICS:
        pub = node.create_publisher(cls, t + '/synced', qos)
        node.create_subscription(cls, t, functools.partial(on, pub), qos)
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.utilities.try_shutdown()


# --- orchestration ---------------------------------------------------------------------------------

def run(kind: str, encoding: str, rate: float, seconds: float, env: dict) -> dict:
    py = sys.executable
    me = str(Path(__file__).resolve())
    if kind == 'evsync_node':
        params = Path(f'/tmp/evsync-bench-{os.getpid()}.yaml')
        params.write_text(json.dumps({'evsync': {'ros__parameters': {
            'topics': TOPICS, 'types': [TYPES[encoding]], 'qos': 'reliable', 'qos_depth': 2000,
            'window_s': 2.0, 'hop_s': 1.0, 'estimate_period_s': 0.5, 'diagnostics_period_s': 0.5}}}))
        node_cmd = [str(Path(py).parent / 'evsync_node'), '--ros-args', '--params-file', str(params)]
    else:
        node_cmd = [py, me, '--role', 'naive', '--encoding', encoding]
    node = subprocess.Popen(node_cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    recv = subprocess.Popen([py, me, '--role', 'receive', '--encoding', encoding, '--seconds', str(seconds)],
                            env=env, stdout=subprocess.PIPE, text=True)
    assert recv.stdout.readline().strip() == 'ready'
    pub = subprocess.Popen([py, me, '--role', 'publish', '--encoding', encoding, '--rate', str(rate),
                            '--seconds', str(seconds)], env=env, stdout=subprocess.PIPE, text=True)
    diagnostics = DiagnosticsListener() if kind == 'evsync_node' else None
    line = pub.stdout.readline().strip()  # built, and the node's subscriptions matched
    assert line == 'sending', f'publisher: {line!r}'
    cpu0, t0 = cpu_seconds(node.pid), time.monotonic()
    tail = pub.stdout.read()
    cpu, wall = cpu_seconds(node.pid) - cpu0, time.monotonic() - t0
    states, diag = diagnostics.close() if diagnostics else (set(), {})
    sent = json.loads(tail.strip().splitlines()[-1])
    received = json.loads(recv.communicate(timeout=seconds + 60)[0].strip().splitlines()[-1])
    node.terminate()
    node.communicate(timeout=20)
    lost = sum(sent['sent']) - sum(received['received'])
    lat = [(float(d['latency_p50_us']), float(d['latency_p99_us'])) for d in diag.values()] if diag else []
    return {
        'node': kind, 'encoding': encoding, 'rate_meps': rate, 'messages': sum(sent['sent']),
        'lost': lost, 'late': sent['late_messages'], 'mb_per_s': sent['bytes'] / 1e6 / seconds,
        'cpu_percent': 100 * cpu / wall if wall else float('nan'),
        'node_p50_us': max((a for a, _ in lat), default=float('nan')),
        'node_p99_us': max((b for _, b in lat), default=float('nan')),
        'e2e_p50_ms': received['e2e_p50_ms'], 'e2e_p99_ms': received['e2e_p99_ms'],
        'states': sorted(states),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--role', choices=['publish', 'receive', 'naive'])
    ap.add_argument('--encoding', choices=list(TYPES), default='evt3')
    ap.add_argument('--rate', type=float, help='aggregate rate, events/s')
    ap.add_argument('--seconds', type=float, default=8.0)
    ap.add_argument('--evt3-rates', type=float, nargs='+', default=[5.0, 10.0, 20.0], metavar='MEV_S')
    ap.add_argument('--dvs-rates', type=float, nargs='+', default=[1.0, 2.0, 4.0], metavar='MEV_S')
    args = ap.parse_args()
    if args.role == 'publish':
        publisher(args.encoding, args.rate, args.seconds)
        return 0
    if args.role == 'receive':
        receiver(args.encoding, args.seconds, '/synced')
        return 0
    if args.role == 'naive':
        naive(args.encoding)
        return 0
    domain = str(random.SystemRandom().randint(101, 200))
    os.environ.update(ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', ROS_DOMAIN_ID=domain)
    env = dict(os.environ)  # this process reads the node's /diagnostics too: one domain for all
    rows = []
    t_start = time.monotonic()
    for encoding, rates in (('evt3', args.evt3_rates), ('dvs', args.dvs_rates)):
        for rate in rates:
            for kind in ('evsync_node', 'naive'):
                r = run(kind, encoding, rate * 1e6, args.seconds, env)
                rows.append(r)
                print(f'  {kind:11s} {encoding} {rate:5.1f} M ev/s: lost {r["lost"]}, cpu {r["cpu_percent"]:.0f} %, '
                      f'e2e p99 {r["e2e_p99_ms"]:.1f} ms', file=sys.stderr, flush=True)
    print(f'4 cameras, {args.seconds:g} s per run, messages of 10 ms, reliable QoS on loopback; '
          f'{len(rows)} runs in {time.monotonic() - t_start:.0f} s\n')
    head = (f'{"node":12s} {"enc":4s} {"M ev/s":>6s} {"msgs":>6s} {"MB/s":>6s} {"lost":>6s} {"cpu %":>6s} '
            f'{"node p50 us":>11s} {"node p99 us":>11s} {"e2e p50 ms":>10s} {"e2e p99 ms":>10s}  states seen')
    print(head)
    print('-' * len(head))
    for r in rows:
        print(f'{r["node"]:12s} {r["encoding"]:4s} {r["rate_meps"] / 1e6:6.1f} {r["messages"]:6d} {r["mb_per_s"]:6.1f} '
              f'{r["lost"]:6d} {r["cpu_percent"]:6.0f} {r["node_p50_us"]:11.0f} {r["node_p99_us"]:11.0f} '
              f'{r["e2e_p50_ms"]:10.2f} {r["e2e_p99_ms"]:10.2f}  {",".join(r["states"])}')
    print('\nlost: messages sent and not received; cpu: the node process (user + system) over the run, '
          '100 % = one core; node p50/p99: receipt to publish inside evsync_node (its /diagnostics at the end '
          'of the run, worst camera); e2e: publisher send to receiver arrival (two DDS hops plus the node); '
          'states seen: in /diagnostics during the run.')
    for encoding in ('evt3', 'dvs'):
        ok = [r for r in rows if r['encoding'] == encoding and r['node'] == 'evsync_node' and r['lost'] == 0]
        nv = [r for r in rows if r['encoding'] == encoding and r['node'] == 'naive' and r['lost'] == 0]
        best = max((r['rate_meps'] for r in ok), default=0) / 1e6
        best_naive = max((r['rate_meps'] for r in nv), default=0) / 1e6
        print(f'{encoding}: highest lossless rate tried: evsync_node {best:g} M ev/s, naive {best_naive:g} M ev/s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
