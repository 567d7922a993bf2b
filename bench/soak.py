"""Soak: evt3 cameras at the drivers' own rate (1 ms packets, best effort KeepLast 1000) through
evsync_node for as long as asked; the node's memory sampled throughout against a ceiling stated
before the run, every message counted out.

    ./dev run python bench/soak.py [--minutes 10] [--rate 1.0] [--cameras 2] [--message-ms 1]
                                   [--qos driver|reliable] [--burst] [--markdown]

(The soak of earlier rounds, 8 cameras in 10 ms messages over reliable QoS: ``--cameras 8
--message-ms 10 --qos reliable``.) Three processes over Fast DDS on loopback:

* **publisher**: ``--cameras`` cameras at ``--rate`` million events/s each, in ``--message-ms``
  EventPacket evt3 messages (metavision_driver sends 1 ms). The scene's activity (a varying event
  rate) repeats every 10.24 s: one cycle of payloads is encoded before the clock starts and sent
  again and again, its TIME_HIGH words moved on by 10.24 s of sensor time per cycle (2500 units of
  4096 us), so sensor time runs on without a break and wraps every 16.8 s as a real sensor's does.
  Every camera sends the same payloads (memory: one cycle, not eight); camera k's header.stamp is its
  send time plus k x 1.7 ms, so its anchored timeline is 1.7 ms x k behind camera 0's and the true
  offset of camera k is -1.7 ms x k. seq counts each camera's messages from 1. With ``--burst``,
  every sixth cycle (61.44 s) carries 0.5 s of messages with ten times the events.
* **evsync_node** with the shipped defaults (refined method, estimate every 1 s, the drivers' QoS,
  before_lock coarse) and the topics; with ``--qos reliable``, reliable depth 2000 everywhere;
* **receiver** of the outputs: messages per camera, seq gaps (lost) and repeats (duplicated), and
  the end-to-end latency (send to arrival, through the node) per minute.

Meanwhile this process samples the node's memory (/proc: VmRSS and its anonymous, file and shared
parts) every 5 s and listens to /diagnostics (states, offsets, bins_bytes). The ceiling, stated
before the run:

    ceiling = RSS when idle (started, subscribed, no event yet) + bins ceiling + 64 MiB + in flight

* bins ceiling: what ``Engine.bins_ceiling_bytes`` allows every stream's density bins (26 s kept
  behind the newest event at 50 us, in whole blocks): 20 MiB for 8 streams;
* 64 MiB: what grows with one message or one window (the decoder's arrays, a window's fit);
* in flight: twice the most bytes the cameras send in any 0.5 s, held once as input and once as
  output not yet acknowledged.

The run passes when no message is lost or duplicated, the peak RSS stays under the ceiling, RSS at
the end is within 5 % of RSS at 2 minutes (bins full: no growth after), and every camera ends
locked within 100 us of its true offset (its last report while messages flowed).

Bursts (``--burst``): a 10x burst outruns the node (about 40 M events in 0.5 s), and the backlog waits
in Fast DDS's histories. rmw_fastrtps's memory policy (PREALLOCATED_WITH_REALLOC) keeps every history
buffer it has grown, so RSS steps up at each burst, by less each time, as more of the buffers have
been grown to a burst message's size; the ceiling above does not hold for it (docs/reliability.md
has the measured steps). Messages are not lost.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import random
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from evsync_testing.evt3cycle import BURST_EVERY, BURST_FACTOR, Cycle
from evsync_testing.measure import QOS_KINDS, DiagnosticsListener, cpu_seconds, qos_profile

TYPE = 'event_camera_msgs/msg/EventPacket'
CAMERA_STEP_NS = 1_700_000
S = 1_000_000_000
HOST_EPOCH = 1_763_700_000 * S
FRAME_DIGITS = 19
SEQ_OFFSET = 44
"""Where an EventPacket's seq sits with a frame_id of FRAME_DIGITS characters (4 encapsulation, 8 stamp,
4 + 20 frame_id, 4 height, 4 width; seq aligned to 8): checked against a parse of the first message."""
LOCK_TOLERANCE_NS = 100_000
ALLOWANCE_BYTES = 64 * 1024 * 1024
QOS_DEPTH = 2000
SETTLED_S = 120.0
"""RSS is compared with its value here: bins full (26 s), the first burst (55 s) over."""


def topics(n: int) -> list[str]:
    return [f'/soak{i}/events' for i in range(n)]


# --- the publisher ---------------------------------------------------------------------------------

def publisher(n_cameras: int, rate: float, seconds: float, burst: bool, message_ns: int, qos_kind: str) -> None:
    import rclpy

    from evsync_ros.ros.messages import message_class
    from msg_adapters.cdr import write_stamp
    from msg_adapters.event_packet import encode_event_packet
    cycle = Cycle(rate * 1e6, message_ns=message_ns)
    if not burst:
        cycle.without_bursts()
    half = cycle.burst_messages  # messages in 0.5 s
    flow = [sum(len(cycle.payload(BURST_EVERY - 1, k)) for k in range(a, a + half)) * n_cameras
            for a in range(0, cycle.per_cycle - half + 1, half)]
    rclpy.init()
    node = rclpy.create_node('soak_publisher')
    qos = qos_profile(qos_kind)
    pubs = [node.create_publisher(message_class(TYPE), t, qos) for t in topics(n_cameras)]
    while any(p.get_subscription_count() < 1 for p in pubs):  # the node's subscriptions
        time.sleep(0.05)
    time.sleep(1.0)
    print('sending', json.dumps({'most_bytes_in_half_a_second': max(flow)}), flush=True)
    total = int(seconds * S // message_ns)
    frame = '0' * FRAME_DIGITS
    start = time.monotonic_ns()
    late = sent = sent_bytes = events = 0
    for i in range(total):
        c, k = divmod(i, cycle.per_cycle)
        send = i * message_ns
        delay = start + send + message_ns - time.monotonic_ns()  # a message goes out when its time is over
        if delay > 0:
            time.sleep(delay / 1e9)
        elif delay < -message_ns:
            late += 1
        base = bytearray(encode_event_packet(stamp_ns=HOST_EPOCH + send + 300_000, frame_id=frame, width=1280,
                                             height=720, seq=i + 1, time_base=0, encoding='evt3',
                                             payload=cycle.payload(c, k)))
        base[16:16 + FRAME_DIGITS] = str(time.monotonic_ns()).rjust(FRAME_DIGITS, '0').encode()
        for cam, pub in enumerate(pubs):
            write_stamp(base, HOST_EPOCH + send + 300_000 + cam * CAMERA_STEP_NS, 'soak')
            pub.publish(bytes(base))
        sent += n_cameras
        events += n_cameras * cycle.events(c, k)
        sent_bytes += n_cameras * len(base)
    elapsed = (time.monotonic_ns() - start) / 1e9
    time.sleep(2.0)
    print(json.dumps({'sent': sent, 'per_camera': total, 'elapsed_s': elapsed, 'late_messages': late,
                      'bytes': sent_bytes, 'events': events}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


# --- the receiver ----------------------------------------------------------------------------------

def receiver(n_cameras: int, expected: int, idle_s: float, qos_kind: str) -> None:
    """Counts every output by seq until each camera has ``expected`` or nothing came for idle_s."""
    import rclpy
    import rclpy.executors

    from evsync_ros.ros.messages import message_class
    from msg_adapters.event_packet import parse_event_packet
    rclpy.init()
    node = rclpy.create_node('soak_receiver')
    qos = qos_profile(qos_kind)
    seen = [np.zeros(expected + 2, np.uint8) for _ in range(n_cameras)]
    malformed = [0] * n_cameras
    distinct = [0] * n_cameras
    """Per camera, the seqs 1..expected seen so far: the run is complete when each has all (counted as they
    come: summing ``seen`` after every message cost O(expected) a message, which at 1 kHz over an hour
    made this receiver, not the node, fall behind)."""
    arrivals: list[int] = []
    latencies: list[int] = []

    seq_at = [0]  # where seq sits in the bytes (fixed: the frame_id has a fixed length), once checked

    def on(cam: int, raw: bytes) -> None:
        now = time.monotonic_ns()
        at = seq_at[0]
        if at:
            seq = int.from_bytes(raw[at:at + 8], 'little')
        else:
            try:
                seq = parse_event_packet(raw).seq
            except Exception:  # noqa: BLE001 (counted: the node must never send one)
                malformed[cam] += 1
                return
            if int.from_bytes(raw[SEQ_OFFSET:SEQ_OFFSET + 8], 'little') == seq:
                seq_at[0] = SEQ_OFFSET
        k = min(seq, expected + 1)
        if not seen[cam][k] and 0 < k <= expected:
            distinct[cam] += 1
        seen[cam][k] += 1
        arrivals.append(now)
        latencies.append(now - int(raw[16:16 + FRAME_DIGITS]))

    for i, t in enumerate(topics(n_cameras)):
        node.create_subscription(message_class(TYPE), t + '/synced', functools.partial(on, i), qos, raw=True)
    print('ready', flush=True)
    # rclpy's EventsExecutor (C++ dispatch), as the node spins: rclpy's Python executor costs this
    # receiver three times as much a message
    try:
        from rclpy.experimental.events_executor import EventsExecutor
        executor: rclpy.executors.Executor = EventsExecutor()
    except ImportError:
        executor = rclpy.executors.SingleThreadedExecutor()  # one executor: rclpy.spin_once(node) builds one a call
    executor.add_node(node)
    last = time.monotonic()
    while True:
        before = len(arrivals)
        executor.spin_once(timeout_sec=0.1)
        if len(arrivals) != before:
            last = time.monotonic()
        done = all(d == expected for d in distinct)
        if done or (arrivals and time.monotonic() - last > idle_s):
            break
    for _ in range(20):  # anything still arriving would be a duplicate
        executor.spin_once(timeout_sec=0.05)
    a, lat = np.array(arrivals, np.int64), np.array(latencies, np.int64) / 1e6
    minutes = (a - a[0]) // (60 * S) if a.size else a
    per_minute = [float(np.percentile(lat[minutes == m], 99)) for m in range(int(minutes.max()) + 1)] if a.size else []
    print(json.dumps({
        'received': int(sum(int(s.sum()) for s in seen)),
        'lost': int(sum(int((s[1:expected + 1] == 0).sum()) for s in seen)),
        'duplicated': int(sum(int(np.maximum(s.astype(np.int64) - 1, 0).sum()) for s in seen)),
        'unexpected_seq': int(sum(int(s[0]) + int(s[expected + 1]) for s in seen)),
        'malformed': sum(malformed),
        'e2e_p50_ms': float(np.percentile(lat, 50)) if lat.size else float('nan'),
        'e2e_p99_ms': float(np.percentile(lat, 99)) if lat.size else float('nan'),
        'e2e_max_ms': float(lat.max()) if lat.size else float('nan'),
        'e2e_p99_per_minute_ms': per_minute}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


# --- orchestration ---------------------------------------------------------------------------------

def memory(pid: int) -> dict[str, int]:
    """VmRSS and its parts (RssAnon: heaps and private maps, RssShmem: shared memory such as Fast DDS's
    transport segments, RssFile: mapped files), bytes."""
    out = {}
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        key = line.split(':', 1)[0]
        if key in ('VmRSS', 'RssAnon', 'RssFile', 'RssShmem'):
            out[key] = int(line.split()[1]) * 1024
    if 'VmRSS' not in out:
        raise RuntimeError(f'no VmRSS for {pid}')
    return out


def rss_bytes(pid: int) -> int:
    return memory(pid)['VmRSS']


class MemorySampler:
    """The node's VmRSS every ``period_s`` in a thread: (seconds since start, bytes)."""

    def __init__(self, pid: int, period_s: float = 5.0) -> None:
        self.pid, self.period_s = pid, period_s
        self.t0 = time.monotonic()
        self.samples: list[tuple[float, int]] = []
        self.parts: list[dict[str, int]] = []
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                m = memory(self.pid)
                self.samples.append((time.monotonic() - self.t0, m['VmRSS']))
                self.parts.append(m)
            except (OSError, RuntimeError):
                return
            self._stop.wait(self.period_s)

    def stop(self) -> list[tuple[float, int]]:
        self._stop.set()
        self.thread.join(timeout=5)
        return self.samples


def _live_diagnostics():

    class LiveDiagnostics(DiagnosticsListener):
        """Also each stream's last report while its messages still flowed (silent under 1 s), since
        every stream is reported lost once the publisher stops."""

        def __init__(self) -> None:
            self.live: dict[str, dict] = {}
            self.live_states: set[str] = set()
            super().__init__()

        def _on(self, msg) -> None:
            super()._on(msg)
            for topic, values in self.newest.items():
                if values.get('silent_s') not in (None, '') and float(values['silent_s']) < 1.0:
                    self.live[topic] = values
                    self.live_states.add(values.get('state', '?'))

    return LiveDiagnostics()


def soak(args: argparse.Namespace) -> dict:
    from evsync_ros.core.engine import Engine, EngineParams
    env = dict(os.environ)
    py = sys.executable
    me = str(Path(__file__).resolve())
    names = topics(args.cameras)
    seconds = args.minutes * 60
    message_ns = int(args.message_ms * 1e6)
    per_camera = int(seconds * S // message_ns)
    params = Path(f'/tmp/evsync-soak-{os.getpid()}.yaml')
    params.write_text(json.dumps({'evsync': {'ros__parameters': {
        'topics': names, 'types': [TYPE], 'reference': names[0],
        **({} if args.qos == 'driver' else {'qos': 'reliable', 'qos_depth': QOS_DEPTH})}}}))  # driver: the defaults
    bins_ceiling = Engine(names, reference=names[0], params=EngineParams()).bins_ceiling_bytes(S)
    node = subprocess.Popen([str(Path(py).parent / 'evsync_node'), '--ros-args', '--params-file', str(params)],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    shape = ['--cameras', str(args.cameras), '--message-ms', str(args.message_ms), '--qos', args.qos]
    recv = subprocess.Popen([py, me, '--role', 'receive', *shape, '--expected', str(per_camera)],
                            env=env, stdout=subprocess.PIPE, text=True)
    assert recv.stdout.readline().strip() == 'ready'
    diagnostics = _live_diagnostics()
    pub = subprocess.Popen([py, me, '--role', 'publish', *shape, '--rate', str(args.rate),
                            '--seconds', str(seconds)] + (['--burst'] if args.burst else []),
                           env=env, stdout=subprocess.PIPE, text=True)
    line = pub.stdout.readline().strip()  # the cycle encoded, the node's subscriptions matched
    assert line.startswith('sending '), f'publisher: {line!r}'
    in_flight = 2 * json.loads(line.split(' ', 1)[1])['most_bytes_in_half_a_second']
    idle = rss_bytes(node.pid)
    ceiling = idle + bins_ceiling + ALLOWANCE_BYTES + in_flight
    print(f'node idle RSS {idle / 2**20:.1f} MiB; ceiling stated: {ceiling / 2**20:.1f} MiB (+ bins '
          f'{bins_ceiling / 2**20:.1f} + {ALLOWANCE_BYTES / 2**20:.0f} + in flight {in_flight / 2**20:.0f} MiB)',
          file=sys.stderr, flush=True)
    sampler = MemorySampler(node.pid)
    cpu0, t0 = cpu_seconds(node.pid), time.monotonic()
    last_print = t0
    while pub.poll() is None:
        time.sleep(1.0)
        if time.monotonic() - last_print >= 60:
            last_print = time.monotonic()
            rss = sampler.samples[-1][1] if sampler.samples else 0
            states = {d.get('state', '?') for d in diagnostics.newest.values()}
            print(f'  {(last_print - t0) / 60:4.1f} min: RSS {rss / 2**20:.1f} MiB, states {sorted(states)}',
                  file=sys.stderr, flush=True)
    sent = json.loads(pub.stdout.read().strip().splitlines()[-1])
    cpu, wall = cpu_seconds(node.pid) - cpu0, time.monotonic() - t0
    received = json.loads(recv.communicate(timeout=120)[0].strip().splitlines()[-1])
    time.sleep(2.0)  # one more /diagnostics after the last message
    samples = sampler.stop()
    diagnostics.close()
    states = diagnostics.live_states
    newest = diagnostics.live
    node.terminate()
    _, err = node.communicate(timeout=30)
    rss_series = np.array([b for _, b in samples], np.int64)
    at = np.array([t for t, _ in samples])
    at_settled = np.searchsorted(at, SETTLED_S) if at.size and at[-1] >= SETTLED_S else -1
    settled = int(rss_series[at_settled])
    truth = {t: -k * CAMERA_STEP_NS for k, t in enumerate(names)}
    cams = []
    for t in names:
        d = newest.get(t, {})
        off = int(d['offset_ns']) if d.get('offset_ns', '') not in ('', None) else None
        cams.append({'topic': t, 'state': d.get('state', '?'), 'offset_ns': off, 'true_ns': truth[t],
                     'error_ns': None if off is None else off - truth[t], 'messages_in': int(d.get('messages_in', 0)),
                     'messages_out': int(d.get('messages_out', 0)), 'malformed': int(d.get('malformed', 0)),
                     'bins_bytes': int(d.get('bins_bytes', 0)), 'windows_accepted': int(d.get('windows_accepted', 0))})
    return {
        'cameras': args.cameras, 'minutes': args.minutes, 'rate_meps_per_camera': args.rate, 'burst': args.burst,
        'message_ms': args.message_ms, 'qos': args.qos,
        'sent': sent, 'received': received, 'cpu_percent': 100 * cpu / wall,
        'rss_idle': idle, 'rss_settled': settled, 'in_flight': in_flight, 'rss_end': int(rss_series[-1]),
        'rss_peak': int(rss_series.max()), 'rss_samples': [(round(t, 1), int(b)) for t, b in samples],
        'rss_parts': sampler.parts, 'bins_ceiling': bins_ceiling, 'ceiling': ceiling,
        'bins_bytes': sum(c['bins_bytes'] for c in cams), 'states_seen': sorted(states), 'per_camera': cams,
        'node_exit': node.returncode, 'node_stderr_tail': err.strip().splitlines()[-3:],
    }


def verdict(r: dict) -> list[str]:
    """What failed (empty: the soak passed)."""
    bad = []
    rec, sent = r['received'], r['sent']
    if rec['lost'] or rec['received'] != sent['sent']:
        bad.append(f'{rec["lost"]} messages lost ({rec["received"]} received of {sent["sent"]})')
    if rec['duplicated'] or rec['unexpected_seq'] or rec['malformed']:
        bad.append(f'{rec["duplicated"]} duplicated, {rec["unexpected_seq"]} unexpected, {rec["malformed"]} malformed')
    if r['rss_peak'] > r['ceiling']:
        bad.append(f'peak RSS {r["rss_peak"] / 2**20:.1f} MiB over the ceiling {r["ceiling"] / 2**20:.1f} MiB')
    if r['rss_end'] > 1.05 * r['rss_settled']:
        bad.append(f'RSS grew from {r["rss_settled"] / 2**20:.1f} to {r["rss_end"] / 2**20:.1f} MiB')
    for c in r['per_camera']:
        if c['state'] != 'locked' or c['error_ns'] is None or abs(c['error_ns']) > LOCK_TOLERANCE_NS:
            bad.append(f'{c["topic"]} ended {c["state"]}, offset error {c["error_ns"]} ns')
    return bad


def table(r: dict, *, markdown: bool) -> str:
    mib = 2 ** 20
    rec, sent = r['received'], r['sent']
    rows = [
        ('cameras x rate', f'{r["cameras"]} x {r["rate_meps_per_camera"]:g} M ev/s '
                           f'(evt3, {r["message_ms"]:g} ms messages, {r["qos"]} QoS)'
                           + (f', a {BURST_FACTOR}x burst of 0.5 s every 61.44 s' if r['burst'] else '')),
        ('duration', f'{sent["elapsed_s"] / 60:.1f} min of sending ({sent["late_messages"]} messages sent late)'),
        ('events, data', f'{sent["events"] / 1e9:.2f} G events, {sent["bytes"] / 1e9:.1f} GB'),
        ('messages sent / received', f'{sent["sent"]} / {rec["received"]}'),
        ('lost / duplicated / malformed', f'{rec["lost"]} / {rec["duplicated"]} / {rec["malformed"]}'),
        ('node CPU', f'{r["cpu_percent"]:.0f} % of one core'),
        ('e2e latency p50 / p99 / max',
         f'{rec["e2e_p50_ms"]:.1f} / {rec["e2e_p99_ms"]:.1f} / {rec["e2e_max_ms"]:.0f} ms'),
        ('e2e p99 per minute', ', '.join(f'{v:.0f}' for v in rec['e2e_p99_per_minute_ms']) + ' ms'),
        ('node RSS idle', f'{r["rss_idle"] / mib:.1f} MiB'),
        (f'node RSS at {SETTLED_S / 60:g} min / end / peak',
         f'{r["rss_settled"] / mib:.1f} / {r["rss_end"] / mib:.1f} / {r["rss_peak"] / mib:.1f} MiB '
         f'(end / {SETTLED_S / 60:g} min = {r["rss_end"] / r["rss_settled"]:.3f})'),
        ('ceiling stated', f'{r["ceiling"] / mib:.1f} MiB = idle + bins ceiling {r["bins_ceiling"] / mib:.1f} '
                           f'+ {ALLOWANCE_BYTES / mib:.0f} + in flight {r["in_flight"] / mib:.0f} MiB; '
                           f'peak uses {r["rss_peak"] / r["ceiling"]:.0%}'),
        ('density bins at the end', f'{r["bins_bytes"] / mib:.1f} MiB (/diagnostics bins_bytes, all streams)'),
        ('states seen while messages flowed', ', '.join(r['states_seen'])),
        ('offsets at the end', '; '.join(
            f'{c["topic"].split("/")[1]} {c["state"]} '
            + ('-' if c['error_ns'] is None else f'{c["error_ns"] / 1e3:+.1f} us')
            for c in r['per_camera'][1:]) + ' (error against the truth)'),
    ]
    bad = verdict(r)
    rows.append(('verdict', 'passed' if not bad else 'FAILED: ' + '; '.join(bad)))
    if markdown:
        return '\n'.join(['| | |', '|---|---|'] + [f'| {k} | {v} |' for k, v in rows])
    w = max(len(k) for k, _ in rows)
    return '\n'.join(f'{k:{w}s}  {v}' for k, v in rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--role', choices=['publish', 'receive'], help=argparse.SUPPRESS)
    ap.add_argument('--cameras', type=int, default=2)
    ap.add_argument('--rate', type=float, default=1.0, help='million events/s per camera (default 1)')
    ap.add_argument('--minutes', type=float, default=10.0)
    ap.add_argument('--seconds', type=float, help=argparse.SUPPRESS)
    ap.add_argument('--expected', type=int, help=argparse.SUPPRESS)
    ap.add_argument('--message-ms', type=float, default=1.0, help='events per message, in ms (drivers: 1)')
    ap.add_argument('--qos', choices=QOS_KINDS, default='driver',
                    help="driver: best effort, KeepLast 1000 (the drivers' and the node's defaults); "
                         'reliable: KeepLast 2000 everywhere')
    ap.add_argument('--burst', action='store_true', help='a 10x burst of 0.5 s every 61.44 s (see the notes)')
    ap.add_argument('--markdown', action='store_true')
    ap.add_argument('--json', metavar='FILE', help='also write every figure, and the RSS samples, to FILE')
    args = ap.parse_args()
    if args.role == 'publish':
        publisher(args.cameras, args.rate, args.seconds, args.burst, int(args.message_ms * 1e6), args.qos)
        return 0
    if args.role == 'receive':
        receiver(args.cameras, args.expected, idle_s=10.0, qos_kind=args.qos)
        return 0
    domain = str(random.SystemRandom().randint(101, 200))
    os.environ.update(ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', ROS_DOMAIN_ID=domain)
    t = time.monotonic()
    r = soak(args)
    if args.json:
        Path(args.json).write_text(json.dumps(r, indent=1))
    print(f'./dev run python bench/soak.py --minutes {args.minutes:g} --rate {args.rate:g} --cameras {args.cameras}'
          f' --message-ms {args.message_ms:g} --qos {args.qos}{" --burst" if args.burst else ""}'
          f'  ({(time.monotonic() - t) / 60:.1f} min in all)\n')
    print(table(r, markdown=args.markdown))
    return 1 if verdict(r) else 0


if __name__ == '__main__':
    sys.exit(main())
