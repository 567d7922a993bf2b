"""One recording through ``evsync estimate`` and through ``evsync_node`` fed by ``evsync play`` at each
pace: the same answer, and what an evt3 consumer decodes from the node's outputs.

    ./dev run python bench/paces.py [--rates 1 2] [--seconds 30] [--seed 5] [--real]

The recording: the simulator's three-camera rig (``--seconds`` long), or with ``--real`` the real
EVK4 recording's two halves as a virtual rig (10.8 s, the second half 1 ms apart; ``../shared/data/
real``). Per pace, the node runs with only topics, types and reference set (``paths.through_node``)
while a listener of this process takes every ``<topic>/synced`` message. Each camera's row:

* ``estimate`` / ``node``: accepted (locked at the end) or not, and the offset's error against the
  truth at the camera's middle (ms);
* ``consumer``: the outputs decoded as an evt3 consumer decodes them (sensor time anchored once, at
  the first packet it receives), each message's events against where the truth puts its input's
  (``nodefaults.message_errors``), the worst over all of them (before the lock: the coarse offset,
  milliseconds) and over the last quarter (locked), in µs; messages paired by ``seq``;
* ``out``: messages received of those sent.
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
from pathlib import Path
from typing import Any


def collect(topics: dict[str, str], domain_id: int) -> tuple[Any, dict[str, list[bytes]]]:
    """A listener in ``domain_id`` taking every ``<topic>/synced`` message raw, best effort as the node
    offers them: (the listener, its messages per topic)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from evsync_ros.ros.messages import message_class
    from evsync_testing.listen import Spinning
    listener = Spinning('paces_outputs', domain_id=domain_id)
    got: dict[str, list[bytes]] = {t: [] for t in topics}
    qos = QoSProfile(depth=20000, reliability=ReliabilityPolicy.BEST_EFFORT)
    for topic, msgtype in topics.items():
        listener.node.create_subscription(message_class(msgtype), f'{topic}/synced', got[topic].append, qos, raw=True)
    listener.start()
    return listener, got


def consumer_errors(sent: list[bytes], out: list[bytes], cam: dict[str, Any]) -> tuple[float, float]:
    """The worst error of the outputs decoded as a consumer does, over all and over the last quarter (µs);
    outputs paired with their inputs by seq."""
    from evsync_testing.nodefaults import message_errors
    from msg_adapters.event_packet import parse_event_packet
    order = {parse_event_packet(raw).seq: i for i, raw in enumerate(sent)}
    kept = [(order[parse_event_packet(raw).seq], raw) for raw in out if parse_event_packet(raw).seq in order]
    errors = message_errors('event_camera_msgs/msg/EventPacket', [sent[i] for i, _ in kept], [r for _, r in kept],
                            cam)
    if not errors:
        return float('nan'), float('nan')
    return max(errors) / 1e3, max(errors[3 * len(errors) // 4:]) / 1e3


def recording(args: argparse.Namespace, where: Path) -> dict[str, Any]:
    """The rig's bag written at ``where``; its truth."""
    if not args.real:
        from evsync_testing.nodefaults import sim_bag
        return sim_bag(where, seconds=args.seconds, seed=args.seed)
    from evsync_testing.realcases import evk4_cases
    from evsync_testing.realdata import read_events, real_data_dir
    from evsync_testing.virtualbag import write_bag
    (events,) = read_events(real_data_dir() / 'evk4_hd').values()
    case = next(c for c in evk4_cases(False) if f'{c.group} {c.name}'.startswith('evk4 halves clean +1.0 ms'))
    return write_bag(case, events, where)


def cell(verdict: Any, cam: dict[str, Any], middles: dict[str, int]) -> str:
    if verdict is None:
        return f'{"-":>16s}'
    error = verdict.error_ns(cam, middles[cam['topic']])
    said = 'accepted' if verdict.accepted else 'refused'
    return f'{said:>8s} {error / 1e6:+7.3f}' if verdict.accepted else f'{said:>16s}'


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--rates', type=float, nargs='+', default=[1.0, 2.0])
    ap.add_argument('--seconds', type=float, default=30.0)
    ap.add_argument('--seed', type=int, default=5)
    ap.add_argument('--real', action='store_true', help='the real EVK4 recording, halves as a virtual rig')
    args = ap.parse_args()
    from evsync_testing import paths
    from evsync_testing.nodefaults import inputs
    with tempfile.TemporaryDirectory(prefix='evsync-paces-') as tmp:
        bag = Path(tmp) / 'rig'
        truth = recording(args, bag)
        cams = {c['topic']: c for c in truth['cameras']}
        middles = paths.middles_of(paths.event_times(bag))
        estimate = paths.through_cli(bag, reference=truth['reference'])
        topics = paths.bag_topics(bag)
        sent = inputs(bag)
        print(f'{"camera":18s} {"estimate (ms)":>16s} {"pace":>5s} {"node (ms)":>16s} {"consumer us all":>15s} '
              f'{"last 1/4":>9s} {"out":>13s}')
        for rate in args.rates:
            domain = random.SystemRandom().randint(1, 200)
            listener, got = collect(topics, domain)
            try:
                node = paths.through_node(bag, reference=truth['reference'], domain_id=domain, rate=rate)
            finally:
                listener.close()
            for topic, cam in cams.items():
                out = got[topic]
                worst = last = float('nan')
                if topics[topic].endswith('EventPacket'):
                    worst, last = consumer_errors(sent[topic], out, cam)
                print(f'{topic:18s} {cell(estimate.get(topic), cam, middles)} {rate:4g}x '
                      f'{cell(node.verdicts.get(topic), cam, middles)} {worst:15.1f} {last:9.1f} '
                      f'{len(out):6d}/{len(sent[topic]):6d}')
    print('estimate, node: accepted (the node: locked at the end) and the offset error at the camera\'s middle; '
          '-: the reference. consumer: an evt3 consumer\'s decode of the outputs against the truth, worst over '
          'every message and over the last quarter (us). out: messages received of those sent.')
    return 0


if __name__ == '__main__':
    sys.exit(main())
