"""Live node throughput at the camera drivers' own rate: messages lost, the node's CPU against a bare
raw relay in the same run, and the latency from receipt to republish.

    ./dev run python bench/node.py [--message-ms 1] [--qos driver|reliable] [--cameras 2 4]
                                   [--evt3-rates 2 5] [--dvs-rates 1] [--seconds 8] [--naive]
                                   [--estimator process|thread|both] [--outputs reliable|best_effort|both]
                                   [--set NAME=VALUE ...]

metavision_driver and libcaer_driver send one EventPacket per millisecond per camera by default
(``event_message_time_threshold`` 1e-3), best effort, KeepLast(1000): that is the default here
(``--message-ms 1 --qos driver``). The outputs (the node's and the relays') are offered, and
received, with ``--outputs``' reliability (default best effort, the node's default
``output_reliability``; ``reliable`` is what a subscriber asks by default), KeepLast(1000). Three
processes per run, over Fast DDS on loopback:

* a publisher sending the cameras' messages (``--message-ms`` of events each, one shared activity,
  clocks seconds apart) at the aggregate rate asked for; every message's frame_id carries its send
  time (CLOCK_MONOTONIC, one clock for every process of this host); EventPackets carry ``seq``;
* the node under test: ``evsync_node`` with only topics, types and reference set (and the QoS:
  the shipped defaults are the drivers'), or a bare relay: an rclpy node that takes each message
  raw and publishes it raw, nothing else, spun by rclpy's EventsExecutor as evsync_node is
  (``relay/ev``, the baseline of ``x relay`` and ``x p99``) or by ``rclpy.spin`` (``relay``, the
  baseline of ``x spin``); or (``--naive``) typed subscriptions and publishers, the message as
  Python objects, restamped field by field;
* a receiver of the outputs: messages per topic, and the end-to-end latency of each (publisher send
  to receiver arrival: two DDS hops plus the node).

The consumer's view (evt3 runs of evsync_node): the receiver keeps every output and, after the run,
decodes it as an evt3 consumer does, sensor time anchored once at the first packet it received
(``consumer_view``), against the true times rebuilt from the publisher's seed; the cameras' evt3
stamps are 1.7 ms apart per camera (``stamp_latency_ns``), so there is an offset to find.

A run is lossless when every message sent came out. The node's own latency (receipt to publish
return) is what it reports in /diagnostics (latency_p50_us, latency_p99_us), with its count of
messages lost upstream (EventPacket seq gaps) and of late callbacks; its CPU is its process's user
+ system time over the run. Messages are built before the clock starts.
"""

from __future__ import annotations

import argparse
import functools
import itertools
import json
import os
import random
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from evsync_ros.runtime.runner import WORKER
from evsync_testing.measure import QOS_KINDS, DiagnosticsListener, children, cpu_seconds, qos_profile

TYPES = {'evt3': 'event_camera_msgs/msg/EventPacket', 'dvs': 'dvs_msgs/msg/EventArray'}
S = 1_000_000_000
HOST_EPOCH = 1_763_700_000 * S
FRAME_DIGITS = 19


# --- the publisher ---------------------------------------------------------------------------------

CONSUMER_SETTLE_NS = 500_000_000
"""The consumer view's packets "after the lock" arrive this long after /diagnostics first said locked
(messages restamped before the lock may still be on their way)."""
PER_CAMERA = 'evsync_node/pc'
"""evsync_node with ``processes: per_camera``."""
SINGLE = 'evsync_node/st'
"""evsync_node with ``executor: single_threaded`` (rclpy.spin)."""
RELAY_EVENTS = 'relay/ev'
"""The relay spun by rclpy's EventsExecutor, as evsync_node is by default: the baseline of ``x relay``."""
THREAD = 'evsync_node/th'
"""evsync_node with ``estimator: thread`` (windows fitted in the node's process)."""


def output_qos(qos_kind: str, outputs: str):
    """The QoS of the outputs, offered and taken: the inputs' (``--qos``), reliable where ``outputs``
    (``output_reliability``) or the inputs are."""
    from rclpy.qos import ReliabilityPolicy
    qos = qos_profile(qos_kind)
    if outputs == 'reliable':
        qos.reliability = ReliabilityPolicy.RELIABLE
    return qos


def topics(cameras: int) -> list[str]:
    return [f'/bench{i}/events' for i in range(cameras)]


def clock_offset_ns(cam: int) -> int:
    """Camera ``cam``'s sensor clock: its true time plus this (seconds apart)."""
    return (cam * 7_300_000_123) % (40 * S) + 123_456


def stamp_latency_ns(cam: int) -> int:
    """How late camera ``cam``'s evt3 header.stamp is on the true time of its packet's first event (a
    driver's host stamp): 0.3 ms, then 1.7 ms more per camera. An evt3 consumer anchors sensor time
    at its first packet's stamp, so the cameras' decoded timelines differ by this; the node finds it."""
    return 300_000 + cam * 1_700_000


def activity(rate: float, seconds: float, cameras: int, seed: int = 0
             ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Per camera, (true times ns, x, y, polarity) of its events: the cameras seeing one activity."""
    rng = np.random.default_rng(seed)
    ms = int(seconds * 1000)
    envelope = np.convolve(rng.random(ms) ** 4, np.ones(20) / 20, mode='same')
    envelope /= envelope.mean()
    per_ms = rate / cameras / 1000 * envelope
    out = []
    for _ in range(cameras):
        n = rng.poisson(per_ms)
        t = np.repeat(np.arange(ms, dtype=np.int64) * 1_000_000, n) + rng.integers(0, 1_000_000, int(n.sum()))
        t.sort()
        x, y = rng.integers(0, 640, t.size), rng.integers(0, 480, t.size)
        p = rng.integers(0, 2, t.size)
        out.append((t, x, y, p))
    return out


def packets(t: np.ndarray, seconds: float, message_ns: int) -> list[tuple[int, int, int]]:
    """(seq, first, end) of a camera's messages over its sorted true times: one per ``message_ns``
    that holds events, seq counting every ``message_ns`` from 1."""
    ms = int(seconds * 1000)
    cuts = np.searchsorted(t, np.arange(0, ms * 1_000_000 + 1, message_ns))
    return [(k + 1, int(a), int(b)) for k, (a, b) in enumerate(zip(cuts[:-1].tolist(), cuts[1:].tolist())) if b > a]


def build_messages(encoding: str, rate: float, seconds: float, cameras: int, message_ns: int, seed: int = 0
                   ) -> list[tuple[int, int, bytearray]]:
    """(send offset ns, camera, serialized message) in send order: the cameras seeing one activity."""
    from msg_adapters.event_array import encode_event_array
    from msg_adapters.event_packet import encode_event_packet
    from msg_adapters.evt3 import encode_evt3
    frame = '0' * FRAME_DIGITS
    out = []
    for cam, (t, x, y, p) in enumerate(activity(rate, seconds, cameras, seed)):
        clock_offset = clock_offset_ns(cam)
        for seq, a, b in packets(t, seconds, message_ns):
            send = seq * message_ns
            cam_t = t[a:b] + clock_offset
            if encoding == 'evt3':
                raw = encode_event_packet(stamp_ns=HOST_EPOCH + int(t[a]) + stamp_latency_ns(cam), frame_id=frame,
                                          width=640, height=480, seq=seq, time_base=0, encoding='evt3',
                                          payload=encode_evt3(cam_t // 1000, x[a:b], y[a:b], p[a:b]))
            else:
                raw = encode_event_array(stamp_ns=int(cam_t[0]), frame_id=frame, width=640, height=480,
                                         t=cam_t, x=x[a:b], y=y[a:b], p=p[a:b])
            out.append((send, cam, bytearray(raw)))
    out.sort(key=lambda m: (m[0], m[1]))
    return out


def publisher(encoding: str, rate: float, seconds: float, cameras: int, message_ns: int, qos_kind: str) -> None:
    import rclpy

    from evsync_ros.ros.messages import message_class
    messages = build_messages(encoding, rate, seconds, cameras, message_ns)
    rclpy.init()
    node = rclpy.create_node('bench_publisher')
    qos = qos_profile(qos_kind)
    pubs = [node.create_publisher(message_class(TYPES[encoding]), t, qos) for t in topics(cameras)]
    deadline = time.monotonic() + 60
    while any(p.get_subscription_count() < 1 for p in pubs):
        if time.monotonic() > deadline:  # the node under test did not start (its stderr says why)
            print('no subscriber matched within 60 s', flush=True)
            return
        time.sleep(0.05)
    time.sleep(1.0)
    print('sending', flush=True)
    start = time.monotonic_ns()
    late = 0
    for send, cam, raw in messages:
        delay = start + send - time.monotonic_ns()
        if delay > 0:
            time.sleep(delay / 1e9)
        elif delay < -message_ns:
            late += 1
        raw[16:16 + FRAME_DIGITS] = str(time.monotonic_ns()).rjust(FRAME_DIGITS, '0').encode()
        pubs[cam].publish(bytes(raw))
    elapsed = (time.monotonic_ns() - start) / 1e9
    time.sleep(1.0)
    counts = [0] * cameras
    for _, cam, _raw in messages:
        counts[cam] += 1
    print(json.dumps({'sent': counts, 'elapsed_s': elapsed, 'late_messages': late,
                      'bytes': sum(len(m[2]) for m in messages)}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


# --- the receiver ----------------------------------------------------------------------------------

def receiver(encoding: str, seconds: float, suffix: str, cameras: int, qos_kind: str, *, outputs: str,
             consumer: Path | None = None, rate: float = 0.0, message_ns: int = 0) -> None:
    """Counts and end-to-end latencies of the outputs; with ``consumer`` (evt3), every output kept and,
    after the run, decoded as a consumer would (``consumer_view``) into that .npz file."""
    import rclpy

    from evsync_ros.ros.messages import message_class
    rclpy.init()
    node = rclpy.create_node('bench_receiver')
    qos = output_qos(qos_kind, outputs)
    counts = [0] * cameras
    latencies: list[int] = []
    # what the consumer view needs, in three lists: neither ints nor bytes are tracked by the garbage
    # collector, where a tuple per message would be (and collections would walk them all)
    kept_cam: list[int] = []
    kept_at: list[int] = []
    kept_raw: list[bytes] = []

    def on(cam: int, raw: bytes) -> None:
        now = time.monotonic_ns()
        counts[cam] += 1
        latencies.append(now - int(raw[16:16 + FRAME_DIGITS]))
        if consumer is not None:
            kept_cam.append(cam)
            kept_at.append(now)
            kept_raw.append(raw)

    for i, t in enumerate(topics(cameras)):
        node.create_subscription(message_class(TYPES[encoding]), t + suffix, functools.partial(on, i), qos, raw=True)
    print('ready', flush=True)
    deadline = None
    while deadline is None or time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
        if deadline is None and any(counts):
            deadline = time.monotonic() + seconds + 4.0
    node.destroy_node()
    rclpy.shutdown()
    if consumer is not None:
        view = consumer_view(list(zip(kept_cam, kept_at, kept_raw)), rate, seconds, cameras, message_ns)
        np.savez(consumer, cam=view['cam'], arrival_ns=view['arrival_ns'], e_min_ns=view['e_min_ns'],
                 e_max_ns=view['e_max_ns'])
    lat = np.array(latencies) / 1e6
    print(json.dumps({'received': counts, 'e2e_p50_ms': float(np.percentile(lat, 50)),
                      'e2e_p99_ms': float(np.percentile(lat, 99))}))


def consumer_view(kept: list[tuple[int, int, bytes]], rate: float, seconds: float, cameras: int, message_ns: int
                  ) -> dict[str, np.ndarray]:
    """What an evt3 consumer of the outputs decodes: per camera one decoder, which anchors sensor time
    at the first packet it receives (as event_camera_codecs does), fed the packets in the order they
    arrived. Per packet: camera, arrival (CLOCK_MONOTONIC ns), and the least and most of decoded time
    minus the event's true time (the activity rebuilt from the publisher's seed; the sensor's
    microseconds as evt3 carries them). On one timeline these differ between cameras by nothing."""
    from msg_adapters.event_packet import EventPacketDecoder
    truth = activity(rate, seconds, cameras)
    index = [{seq: (a, b) for seq, a, b in packets(t, seconds, message_ns)} for t, *_ in truth]
    decoders = [EventPacketDecoder() for _ in range(cameras)]
    rows = []
    for cam, arrival, raw in kept:
        view, events = decoders[cam].decode(raw)
        a, b = index[cam][view.seq]
        off = clock_offset_ns(cam)
        true = (truth[cam][0][a:b] + off) // 1000 * 1000 - off
        if events.t.size != true.size:
            raise SystemExit(f'camera {cam} packet seq {view.seq}: {events.t.size} events out, {true.size} sent')
        e = events.t - true
        rows.append((cam, arrival, int(e.min()), int(e.max())))
    table = np.array(rows, dtype=np.int64).reshape(-1, 4)
    return {'cam': table[:, 0], 'arrival_ns': table[:, 1], 'e_min_ns': table[:, 2], 'e_max_ns': table[:, 3]}


def consumer_errors(view: dict[str, np.ndarray], locked_at: dict[int, int], *, settle_ns: int) -> dict:
    """From ``consumer_view``'s table: how far each camera's decoded events are from the reference's
    timeline (camera 0's decoded time minus true time, its median), over the packets that arrived
    ``settle_ns`` after the node first reported the camera locked (``locked_at``: CLOCK_MONOTONIC ns)
    and over those before: every camera but the reference together, in microseconds; NaN for none."""
    cam, arrival = view['cam'], view['arrival_ns']
    ref = cam == 0
    if not ref.any():
        return {}
    mid = (view['e_min_ns'] + view['e_max_ns']) / 2
    d = float(np.median(mid[ref]))
    err = np.maximum(np.abs(view['e_min_ns'] - d), np.abs(view['e_max_ns'] - d)) / 1e3
    after, before, unlocked = [], [], 0
    for c in sorted(set(cam.tolist()) - {0}):
        mine = cam == c
        if c not in locked_at:
            unlocked += 1
            before.append(err[mine])
            continue
        late = arrival >= locked_at[c] + settle_ns
        after.append(err[mine & late])
        before.append(err[mine & ~late])
    a = np.concatenate(after) if after else np.empty(0)
    b = np.concatenate(before) if before else np.empty(0)
    return {'consumer_ref_spread_us': float(err[ref].max()),
            'consumer_after_p50_us': float(np.percentile(a, 50)) if a.size else float('nan'),
            'consumer_after_p99_us': float(np.percentile(a, 99)) if a.size else float('nan'),
            'consumer_after_max_us': float(a.max()) if a.size else float('nan'),
            'consumer_after_packets': int(a.size),
            'consumer_before_max_us': float(b.max()) if b.size else float('nan'),
            'consumer_unlocked': unlocked}


# --- the naive node --------------------------------------------------------------------------------

def relay(encoding: str, cameras: int, qos_kind: str, executor: str = 'single_threaded', *,
          outputs: str = 'reliable') -> None:
    """The baseline: each message taken raw and published raw, nothing else (``rclpy.spin``, or
    ``executor`` events: as evsync_node spins)."""
    import rclpy

    from evsync_ros.ros.messages import message_class
    rclpy.init()
    node = rclpy.create_node('bench_relay')
    qos = qos_profile(qos_kind)
    cls = message_class(TYPES[encoding])
    for t in topics(cameras):
        pub = node.create_publisher(cls, t + '/synced', output_qos(qos_kind, outputs))
        node.create_subscription(cls, t, pub.publish, qos, raw=True)
    _spin(node, executor)


def _spin(node, executor: str = 'single_threaded') -> None:
    """Spin a baseline node until it is terminated."""
    import rclpy

    from evsync_ros.ros.modes import Executor
    from evsync_ros.ros.spin import spin
    try:
        spin(node, executor=Executor(executor))
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.utilities.try_shutdown()


def naive(encoding: str, cameras: int, qos_kind: str, *, outputs: str = 'reliable') -> None:
    """Typed subscriptions, Python objects, a fixed correction applied field by field."""
    import rclpy

    from evsync_ros.ros.messages import message_class
    rclpy.init()
    node = rclpy.create_node('bench_naive')
    qos = qos_profile(qos_kind)
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

    for t in topics(cameras):
        pub = node.create_publisher(cls, t + '/synced', output_qos(qos_kind, outputs))
        node.create_subscription(cls, t, functools.partial(on, pub), qos)
    _spin(node)


# --- orchestration ---------------------------------------------------------------------------------

def idle_seconds() -> float:
    """Seconds every core of this host has been idle so far (/proc/stat)."""
    fields = Path('/proc/stat').read_text().split('\n', 1)[0].split()
    return int(fields[4]) / os.sysconf('SC_CLK_TCK')


def is_estimator(pid: int) -> bool:
    """Whether ``pid`` is evsync_node's estimator process (``runner.WORKER``), not a camera process."""
    try:
        return WORKER.encode() in Path(f'/proc/{pid}/cmdline').read_bytes().split(b'\0')
    except OSError:
        return False


def run(kind: str, encoding: str, rate: float, seconds: float, cameras: int, message_ns: int, qos_kind: str,
        env: dict, extra: dict | None = None, outputs: str = 'reliable') -> dict:
    py = sys.executable
    me = str(Path(__file__).resolve())
    shape = ['--encoding', encoding, '--cameras', str(cameras), '--qos', qos_kind, '--outputs', outputs]
    if kind.startswith('evsync_node'):
        params = Path(f'/tmp/evsync-bench-{os.getpid()}.yaml')
        values: dict = {'topics': topics(cameras), 'types': [TYPES[encoding]]}
        if kind == PER_CAMERA:
            values['processes'] = 'per_camera'
        if kind == SINGLE:
            values['executor'] = 'single_threaded'
        if kind == THREAD:
            values['estimator'] = 'thread'
        if qos_kind != 'driver':  # else the shipped defaults, which are the drivers'
            values.update(qos='reliable', qos_depth=2000)
        values['output_reliability'] = outputs
        values.update(extra or {})
        params.write_text(json.dumps({'evsync': {'ros__parameters': values}}))
        node_cmd = [str(Path(py).parent / 'evsync_node'), '--ros-args', '--params-file', str(params)]
    elif kind == RELAY_EVENTS:
        node_cmd = [py, me, '--role', 'relay', '--spin', 'events', *shape]
    else:
        node_cmd = [py, me, '--role', kind, *shape]
    node = subprocess.Popen(node_cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    view_file = Path(f'/tmp/evsync-bench-consumer-{os.getpid()}.npz')
    view_file.unlink(missing_ok=True)
    consumer = kind.startswith('evsync_node') and encoding == 'evt3'
    recv = subprocess.Popen([py, me, '--role', 'receive', *shape, '--seconds', str(seconds),
                             *(['--consumer', str(view_file), '--rate', str(rate),
                                '--message-ms', str(message_ns / 1e6)] if consumer else [])],
                            env=env, stdout=subprocess.PIPE, text=True)
    assert recv.stdout.readline().strip() == 'ready'
    pub = subprocess.Popen([py, me, '--role', 'publish', *shape, '--rate', str(rate), '--seconds', str(seconds),
                            '--message-ms', str(message_ns / 1e6)], env=env, stdout=subprocess.PIPE, text=True)
    diagnostics = DiagnosticsListener() if kind.startswith('evsync_node') else None
    line = pub.stdout.readline().strip()  # built, and the node's subscriptions matched
    if line != 'sending':
        node.terminate()
        recv.terminate()
        raise SystemExit(f'{kind} with {cameras} cameras: publisher said {line!r}; the node said: '
                         f'{node.communicate(timeout=20)[1].strip()[-2000:]}')
    family = [node.pid, *children(node.pid)]  # per_camera: the camera processes are up by now
    others = [pub.pid, recv.pid]
    cpu0, t0, idle0 = [cpu_seconds(p) for p in family + others], time.monotonic(), idle_seconds()
    tail = pub.stdout.read()
    used, wall = [cpu_seconds(p) - c for p, c in zip(family + others, cpu0)], time.monotonic() - t0
    idle = idle_seconds() - idle0
    (pub_cpu, recv_cpu), used = used[len(family):], used[:len(family)]
    cpu = sum(used)
    workers = {p for p in family[1:] if is_estimator(p)}
    estimator = [u for p, u in zip(family, used) if p in workers]
    cams = [u for p, u in zip(family[1:], used[1:]) if p not in workers]
    locked_at = dict(diagnostics.locked_at) if diagnostics else {}
    states, diag = diagnostics.close() if diagnostics else (set(), {})
    sent = json.loads(tail.strip().splitlines()[-1])
    received = json.loads(recv.communicate(timeout=seconds + 120)[0].strip().splitlines()[-1])
    view: dict = {}
    if consumer:
        with np.load(view_file) as table:
            names = topics(cameras)
            view = consumer_errors(dict(table), {names.index(t): at for t, at in locked_at.items() if t in names},
                                   settle_ns=CONSUMER_SETTLE_NS)
        view_file.unlink()
    node.terminate()
    try:
        node.communicate(timeout=20)
    except subprocess.TimeoutExpired:  # a node still working through its backlog
        node.kill()
        node.communicate()
    lost = sum(sent['sent']) - sum(received['received'])
    lat = [(float(d['latency_p50_us']), float(d['latency_p99_us'])) for d in diag.values()] if diag else []
    return {
        'node': kind, 'outputs': outputs, 'encoding': encoding, 'cameras': cameras, 'rate_meps': rate,
        'messages': sum(sent['sent']),
        'lost': lost, 'late': sent['late_messages'], 'mb_per_s': sent['bytes'] / 1e6 / seconds,
        'cpu_percent': 100 * cpu / wall if wall else float('nan'),
        'processes': len(family),
        'camera_cpu_percent': 100 * max(cams) / wall if cams and wall else float('nan'),
        'publisher_cpu_percent': 100 * pub_cpu / wall if wall else float('nan'),
        'receiver_cpu_percent': 100 * recv_cpu / wall if wall else float('nan'),
        'host_idle_percent': 100 * idle / wall / (os.cpu_count() or 1) if wall else float('nan'),
        'estimator_cpu_percent': 100 * sum(estimator) / wall if estimator and wall else float('nan'),
        'node_p50_us': max((a for a, _ in lat), default=float('nan')),
        'node_p99_us': max((b for _, b in lat), default=float('nan')),
        'seq_lost': sum(int(d.get('messages_lost', 0) or 0) for d in diag.values()) if diag else 0,
        'late_callbacks': sum(int(d.get('late_callbacks', 0) or 0) for d in diag.values()) if diag else 0,
        'e2e_p50_ms': received['e2e_p50_ms'], 'e2e_p99_ms': received['e2e_p99_ms'],
        'states': sorted(states), **view,
    }


def baseline(rows: list[dict], r: dict, kind: str) -> dict | None:
    """The run of relay ``kind`` in the conditions of ``r`` (same encoding, outputs, cameras, rate)."""
    same = ('encoding', 'outputs', 'cameras', 'rate_meps')
    return next((b for b in rows if b['node'] == kind and all(b[k] == r[k] for k in same)), None)


def cpu_ratio(rows: list[dict], r: dict, kind: str) -> float:
    """``r``'s CPU over the relay ``kind``'s in the same conditions (NaN: no such run)."""
    base = baseline(rows, r, kind)
    return r['cpu_percent'] / base['cpu_percent'] if base and base['cpu_percent'] else float('nan')


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--role', choices=['publish', 'receive', 'naive', 'relay'])
    ap.add_argument('--encoding', choices=list(TYPES), default='evt3')
    ap.add_argument('--rate', type=float, help='aggregate rate, events/s')
    ap.add_argument('--seconds', type=float, default=8.0)
    ap.add_argument('--message-ms', type=float, default=1.0, help='events per message, in ms (drivers: 1)')
    ap.add_argument('--qos', choices=QOS_KINDS, default='driver',
                    help='driver: best effort, KeepLast 1000 (the drivers\' and the node\'s defaults)')
    ap.add_argument('--outputs', choices=['reliable', 'best_effort', 'both'], default='best_effort',
                    help="reliability of the outputs, the node's (output_reliability) and the relays', and of their "
                         'receiver (both: a run of each)')
    ap.add_argument('--cameras', type=int, nargs='+', default=[2, 4],
                    help='cameras per run (evsync_node takes two to eight)')
    ap.add_argument('--evt3-rates', type=float, nargs='*', default=[2.0, 5.0], metavar='MEV_S')
    ap.add_argument('--dvs-rates', type=float, nargs='*', default=[1.0], metavar='MEV_S')
    ap.add_argument('--naive', action='store_true', help='also the typed naive node')
    ap.add_argument('--processes', choices=['one', 'per_camera', 'both'], default='one',
                    help="evsync_node's processes parameter (both: a run of each)")
    ap.add_argument('--executor', choices=['events', 'single_threaded', 'both'], default='events',
                    help="evsync_node's executor parameter (both: a run of each, processes one)")
    ap.add_argument('--estimator', choices=['process', 'thread', 'both'], default='process',
                    help="evsync_node's estimator parameter (both: a run of each, processes one)")
    ap.add_argument('--relay-events', action='store_true', help=argparse.SUPPRESS)  # now always run: the baseline
    ap.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                    help='a parameter of evsync_node beyond the defaults, its value as JSON (a double with its '
                         'decimal point: estimate_period_s=60.0); repeatable')
    ap.add_argument('--spin', choices=['events', 'single_threaded'], default='single_threaded',
                    help=argparse.SUPPRESS)
    ap.add_argument('--consumer', type=Path, help=argparse.SUPPRESS)  # the receiver's consumer view file
    args = ap.parse_args()
    message_ns = int(args.message_ms * 1e6)
    if args.role == 'publish':
        publisher(args.encoding, args.rate, args.seconds, args.cameras[0], message_ns, args.qos)
        return 0
    if args.role == 'receive':
        receiver(args.encoding, args.seconds, '/synced', args.cameras[0], args.qos, outputs=args.outputs,
                 consumer=args.consumer,
                 rate=args.rate or 0.0, message_ns=message_ns)
        return 0
    if args.role == 'naive':
        naive(args.encoding, args.cameras[0], args.qos, outputs=args.outputs)
        return 0
    if args.role == 'relay':
        relay(args.encoding, args.cameras[0], args.qos, args.spin, outputs=args.outputs)
        return 0
    extra = {}
    for item in args.set:
        name, sep, value = item.partition('=')
        if not sep or not name:
            ap.error(f'--set takes NAME=VALUE, got {item!r}')
        try:
            extra[name] = json.loads(value)  # a number, true/false, a list
        except json.JSONDecodeError:
            extra[name] = value  # a string
    domain = str(random.SystemRandom().randint(101, 200))
    os.environ.update(ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', ROS_DOMAIN_ID=domain)
    env = dict(os.environ)  # this process reads the node's /diagnostics too: one domain for all
    rows = []
    t_start = time.monotonic()
    nodes = {'one': ('evsync_node',), 'per_camera': (PER_CAMERA,), 'both': ('evsync_node', PER_CAMERA)}
    kinds = nodes[args.processes]
    if args.executor == 'single_threaded':
        kinds = tuple(SINGLE if k == 'evsync_node' else k for k in kinds)
    elif args.executor == 'both':
        kinds += (SINGLE,)
    if args.estimator == 'thread':
        kinds = tuple(THREAD if k == 'evsync_node' else k for k in kinds)
    elif args.estimator == 'both':
        kinds += (THREAD,)
    reliabilities = ('reliable', 'best_effort') if args.outputs == 'both' else (args.outputs,)
    kinds += (RELAY_EVENTS, 'relay') + (('naive',) if args.naive else ())
    for encoding, rates in (('evt3', args.evt3_rates), ('dvs', args.dvs_rates)):
        for cameras in args.cameras:
            for rate in rates:
                for kind, outputs in itertools.product(kinds, reliabilities):
                    r = run(kind, encoding, rate * 1e6, args.seconds, cameras, message_ns, args.qos, env, extra,
                            outputs)
                    rows.append(r)
                    print(f'  {kind:11s} {outputs:11s} {encoding} {cameras} cam {rate:5.1f} M ev/s: lost {r["lost"]}, '
                          f'cpu {r["cpu_percent"]:.0f} %, e2e p99 {r["e2e_p99_ms"]:.1f} ms',
                          file=sys.stderr, flush=True)
    print(f'{args.seconds:g} s per run, messages of {args.message_ms:g} ms per camera, {args.qos} QoS on loopback; '
          f'{len(rows)} runs in {time.monotonic() - t_start:.0f} s\n')
    head = (f'{"node":12s} {"outputs":11s} {"enc":4s} {"cams":>4s} {"M ev/s":>6s} {"msgs":>6s} {"lost":>5s} '
            f'{"cpu %":>6s} '
            f'{"x relay":>7s} {"x spin":>6s} {"x p99":>6s} '
            f'{"node p50 us":>11s} {"node p99 us":>11s} {"e2e p50 ms":>10s} {"e2e p99 ms":>10s} '
            f'{"seq lost":>8s} {"late cb":>7s} {"procs":>5s} {"cam cpu %":>9s} {"est cpu %":>9s} {"pub cpu %":>9s} '
            f'{"recv cpu %":>10s} {"idle %":>6s} {"cons p99 us":>11s} {"cons max us":>11s} {"pre-lock ms":>11s}'
            f'  states seen')
    print(head)
    print('-' * len(head))
    nan = float('nan')
    for r in rows:
        ratio, spin = (cpu_ratio(rows, r, kind) for kind in (RELAY_EVENTS, 'relay'))
        base = baseline(rows, r, RELAY_EVENTS)
        p99 = r['e2e_p99_ms'] / base['e2e_p99_ms'] if base and base['e2e_p99_ms'] else nan
        print(f'{r["node"]:12s} {r["outputs"]:11s} {r["encoding"]:4s} {r["cameras"]:4d} {r["rate_meps"] / 1e6:6.1f} '
              f'{r["messages"]:6d} '
              f'{r["lost"]:5d} {r["cpu_percent"]:6.0f} {ratio:7.2f} {spin:6.2f} {p99:6.2f} '
              f'{r["node_p50_us"]:11.0f} {r["node_p99_us"]:11.0f} '
              f'{r["e2e_p50_ms"]:10.2f} {r["e2e_p99_ms"]:10.2f} {r["seq_lost"]:8d} {r["late_callbacks"]:7d} '
              f'{r["processes"]:5d} {r["camera_cpu_percent"]:9.0f} {r["estimator_cpu_percent"]:9.0f} '
              f'{r["publisher_cpu_percent"]:9.0f} {r["receiver_cpu_percent"]:10.0f} {r["host_idle_percent"]:6.0f} '
              f'{r.get("consumer_after_p99_us", nan):11.0f} {r.get("consumer_after_max_us", nan):11.0f} '
              f'{r.get("consumer_before_max_us", nan) / 1e3:11.2f}  {",".join(r["states"])}')
    print('\noutputs: the reliability the node and the relays offer their outputs with, and the receiver asks '
          '(KeepLast 1000); lost: messages sent and not received; cpu: the node\'s processes (user + system, '
          'summed) over the run, '
          '100 % = one core; procs: its processes; evsync_node: the shipped defaults (one process and its '
          'estimator process, rclpy\'s EventsExecutor); evsync_node/pc: processes per_camera (the estimator '
          'and a process per camera); '
          'evsync_node/st: executor single_threaded (rclpy.spin); relay/ev: the bare raw relay on rclpy\'s '
          'EventsExecutor, as evsync_node spins, the baseline of x relay (its cpu over relay/ev\'s, same '
          'conditions, same run) and of x p99 (its e2e p99 over relay/ev\'s); relay: that relay on rclpy.spin, '
          'the baseline of x spin; cam cpu: '
          'the busiest camera process; est cpu: the estimator process (estimator: process, the default; '
          'evsync_node/th: estimator thread, in the node\'s process), within cpu; '
          'pub cpu, recv cpu: the benchmark\'s own publisher and receiver; idle: the host\'s cores idle over the '
          'run (100 % = all of them); '
          'node p50/p99: receipt to publish '
          'inside evsync_node (its /diagnostics at the end of the run, worst camera); e2e: publisher send to '
          'receiver arrival (two DDS hops plus the node); seq lost: messages the node saw missing from EventPacket '
          'seq; late cb: callbacks the node took late; states seen: in /diagnostics during the run; '
          'cons: the consumer\'s view (evt3, evsync_node): the outputs decoded as an evt3 consumer does (sensor '
          'time anchored once, at the first packet it receives), each camera\'s events against where the '
          'reference\'s put the same true time; cons p99/max: over the packets that arrived 0.5 s after '
          '/diagnostics first said the camera locked, every camera but the reference; pre-lock: the largest '
          'before (before_lock: coarse; the cameras\' evt3 stamps are 1.7 ms apart per camera).')
    return 0


if __name__ == '__main__':
    sys.exit(main())
