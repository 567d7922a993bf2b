"""The node's own work per message, in process: CPU per message through its message path
(``EvsyncNode.path.on_message``: decode, bin, restamp, raw publish), the messages of ``bench/node.py``
fed at their send times with no transport in front, the estimator stepped once per second of them.

    ./dev run python bench/message_path.py [--cameras 4] [--rate 5] [--seconds 12] [--message-ms 1]
                                           [--profile 25] [--stages] [--triggers]

It prints the CPU per message before the lock (the first seconds: ``before_lock`` coarse) and once
the cameras are locked, and the estimator's CPU per second of data. ``--profile N``: where a locked
message's microseconds go, the N functions of the message path that take the most of them on their
own (cProfile, whose own cost inflates every figure alike: read it as shares). ``--triggers``: every
camera with ``trigger_channels`` (channel 0), its messages read for trigger edges too. What rclpy spends taking a
message from DDS is not in it (``bench/node.py`` measures the whole node against a bare relay).
"""

from __future__ import annotations

import argparse
import cProfile
import functools
import os
import pstats
import random
import time
from pathlib import Path
from typing import Any

from node import TYPES, S, build_messages, topics  # type: ignore[import-not-found]  # bench/node.py, beside this file


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--cameras', type=int, default=4)
    ap.add_argument('--rate', type=float, default=5.0, help='aggregate million events/s')
    ap.add_argument('--seconds', type=float, default=12.0)
    ap.add_argument('--message-ms', type=float, default=1.0)
    ap.add_argument('--profile', type=int, default=0, metavar='N', help="the N functions a locked message's time "
                    'goes to most (cProfile)')
    ap.add_argument('--stages', action='store_true', help="a locked message's time by stage, each timed")
    ap.add_argument('--triggers', action='store_true', help='every camera with trigger_channels (channel 0)')
    args = ap.parse_args()
    os.environ.update(ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                      ROS_DOMAIN_ID=str(random.SystemRandom().randint(101, 200)))
    import rclpy
    from rclpy.parameter import Parameter

    from evsync_ros.ros.node import EvsyncNode
    msgs = build_messages('evt3', args.rate * 1e6, args.seconds, args.cameras, int(args.message_ms * 1e6))
    rclpy.init()
    now = [0]
    names = topics(args.cameras)
    triggers = [Parameter('trigger_channels', value=[f'{t}=0' for t in names])] if args.triggers else []
    node = EvsyncNode(parameter_overrides=[Parameter('topics', value=names), Parameter('types', value=[TYPES['evt3']]),
                                           *triggers], clock=lambda: now[0])
    streams = [node.path.streams[t] for t in names]
    stages = Stages(node) if args.stages else None
    on_message, sync = node.path.on_message, node.estimator.sync
    cpu = {'before the lock': [0.0, 0], 'locked': [0.0, 0]}
    step_cpu, next_step = 0.0, S
    profiler = cProfile.Profile() if args.profile else None
    try:
        for send, cam, raw in msgs:
            now[0] = send
            if send >= next_step:
                t0 = time.process_time()
                sync.step(send)
                step_cpu += time.process_time() - t0
                next_step += S
            locked = all(sync.correction(t) is not None for t in names)
            data = bytes(raw)
            if locked and profiler is not None:
                profiler.enable()
            if stages is not None:
                stages.on = locked
            t0 = time.process_time()
            on_message(streams[cam], data)
            if profiler is not None:
                profiler.disable()
            part = cpu['locked' if locked else 'before the lock']
            part[0] += time.process_time() - t0
            part[1] += 1
    finally:
        node.destroy_node()
        rclpy.shutdown()
    events = args.rate * 1e6 / args.cameras * args.message_ms / 1e3
    print(f'{args.cameras} evt3 cameras{" with trigger_channels" if args.triggers else ""}, {args.rate:g} M events/s '
          f'in all, {args.message_ms:g} ms messages (~{events:,.0f} events each), {args.seconds:g} s')
    for what, (seconds, n) in cpu.items():
        if n:
            print(f'  {what:16s} {n:7d} messages  {seconds / n * 1e6:6.1f} us CPU per message')
    print(f'  estimator        {step_cpu / args.seconds * 1e3:6.1f} ms CPU per second of data')
    if profiler is not None:
        show_profile(profiler, int(cpu['locked'][1]), args.profile)
    if stages is not None:
        stages.show()
    return 0


class Stages:
    """Wall time of each stage of the message path, for the messages while ``on``: the path's
    ``on_message``, the decoder's ``step``, the C call in it, the sink's ``counted`` and ``_publish``
    each wrapped by a timer."""

    def __init__(self, node: Any) -> None:
        from msg_adapters import _kernels
        from msg_adapters.event_packet import EventPacketDecoder
        self.on = False
        self.ns: dict[str, int] = {}
        self.calls: dict[str, int] = {}
        path = node.path
        self._wrap(path, 'on_message', 'message')
        self._wrap(EventPacketDecoder, 'step', 'step')
        for name in ('evt3_packet_step', 'cmp_packet_step', 'libcaer_packet_step', 'mono_packet_step'):
            self._wrap(_kernels, name, 'C call')  # looked up in the module at each call
        self._wrap(path.sink, 'counted', 'feed')
        self._wrap(path, '_publish', 'publish')
        self.timer_us = self._timer_cost()
        """What a timer adds to the stage around its call (us): taken out of that stage's figure."""

    def _wrap(self, owner: Any, name: str, label: str) -> None:
        setattr(owner, name, Timed(getattr(owner, name), self, label))

    def _timer_cost(self, calls: int = 50_000) -> float:
        """A method's call through a timer, less its plain call (us): the larger of a few tries."""
        class Probe:
            def plain(self) -> None: ...

        Probe.timed = Timed(Probe.plain, self, 'probe')  # type: ignore[attr-defined]
        probe, self.on, best = Probe(), True, 0.0
        for _ in range(3):
            t0 = time.perf_counter_ns()
            for _ in range(calls):
                probe.timed()  # type: ignore[attr-defined]
            t1 = time.perf_counter_ns()
            for _ in range(calls):
                probe.plain()
            best = max(best, ((t1 - t0) - (time.perf_counter_ns() - t1)) / calls / 1e3)
        self.on = False
        self.ns.pop('probe'), self.calls.pop('probe')
        return best

    def show(self) -> None:
        n = max(self.calls.get('message', 0), 1)
        us = {k: v / n / 1e3 for k, v in self.ns.items()}
        inner = {k: v / n for k, v in self.calls.items()}  # timed calls per message, by stage
        timer = self.timer_us
        rows = [('the C call (decode, count, retime, output)', us.get('C call', 0.0)),
                ("its decoder's Python around it", us.get('step', 0.0) - us.get('C call', 0.0)
                 - timer * inner.get('C call', 0.0)),
                ("the estimate's feed", us.get('feed', 0.0)), ('the publish', us.get('publish', 0.0))]
        whole = us.get('message', 0.0) - timer * sum(v for k, v in inner.items() if k != 'message')
        rows.append(('the rest of the path', whole - sum(v for _, v in rows)))
        print(f"\nwhere a locked message's time goes ({self.calls.get('message', 0)} messages, wall us each, "
              f'{whole:.1f} in all; each of its {sum(inner.values()) - 1:.0f} inner timers, {timer:.2f} us, taken out)')
        for what, v in rows:
            print(f'  {v:6.1f}  {what}')


class Timed:
    """``fn``, its wall time added to ``stages`` under ``label`` while ``stages.on``."""

    def __init__(self, fn: Any, stages: Stages, label: str) -> None:
        self.fn, self.stages, self.label = fn, stages, label

    def __get__(self, obj: Any, owner: Any = None) -> Any:  # a method: bound as the function it wraps
        return self if obj is None else functools.partial(self.__call__, obj)

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if not self.stages.on:
            return self.fn(*args, **kwargs)
        t0 = time.perf_counter_ns()
        try:
            return self.fn(*args, **kwargs)
        finally:
            st = self.stages
            st.ns[self.label] = st.ns.get(self.label, 0) + time.perf_counter_ns() - t0
            st.calls[self.label] = st.calls.get(self.label, 0) + 1


def show_profile(profiler: cProfile.Profile, messages: int, top: int) -> None:
    """Each of the ``top`` functions' own time and cumulative time per locked message (us), and its
    calls per message."""
    stats = pstats.Stats(profiler).stats  # type: ignore[attr-defined]  # {(file, line, name): (cc, nc, tt, ct, _)}
    each = sum(v[2] for v in stats.values()) / max(messages, 1) * 1e6
    print(f'\nwhere a locked message goes ({messages} messages, profiled: {each:.1f} us each)')
    print(f'  {"own us":>7s} {"cum us":>7s} {"calls":>6s}  function')
    for (file, line, name), (_, calls, own, cum, _) in sorted(stats.items(), key=lambda kv: -kv[1][2])[:top]:
        where = f'{Path(file).name}:{line}' if line else file
        print(f'  {own / messages * 1e6:7.2f} {cum / messages * 1e6:7.2f} {calls / messages:6.2f}  {name} ({where})')


if __name__ == '__main__':
    raise SystemExit(main())
