"""How long a full garbage collection stops evsync_node's process, with and without ``gc.freeze``.

    ./dev run python bench/gc_pause.py [--cameras 4] [--repeat 5]

A full (generation 2) collection walks every object the process tracks and holds the interpreter
meanwhile: the message callbacks wait for it. Most of what evsync_node tracks is there from its start
(rclpy, numpy, the node itself) and is never garbage; ``main`` freezes it (``gc.freeze``) before it
spins, so that collections walk only what came after. This builds the node as ``main`` does (EvsyncNode
with only topics and types set), then times full collections before and after the freeze, in the same
process.
"""

from __future__ import annotations

import argparse
import gc
import json
import statistics
import tempfile
import time
from pathlib import Path


def full_collection_ms() -> float:
    t = time.perf_counter()
    gc.collect(2)
    return (time.perf_counter() - t) * 1e3


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--cameras', type=int, default=4)
    ap.add_argument('--repeat', type=int, default=5)
    args = ap.parse_args()
    import rclpy

    from evsync_ros.ros.node import EvsyncNode
    topics = [f'/cam{i}/events' for i in range(args.cameras)]
    with tempfile.TemporaryDirectory() as tmp:
        params = Path(tmp) / 'params.yaml'
        params.write_text(json.dumps({'evsync': {'ros__parameters': {
            'topics': topics, 'types': ['event_camera_msgs/msg/EventPacket']}}}))
        rclpy.init(args=['--ros-args', '--params-file', str(params)])
        node = EvsyncNode()
        try:
            tracked = len(gc.get_objects())
            before = [full_collection_ms() for _ in range(args.repeat)]
            gc.freeze()
            frozen = gc.get_freeze_count()
            after = [full_collection_ms() for _ in range(args.repeat)]
        finally:
            gc.unfreeze()
            node.destroy_node()
            rclpy.shutdown()
    print(f'evsync_node with {args.cameras} cameras: {tracked} objects tracked, {frozen} frozen')
    print(f'full collection, ms (median of {args.repeat}): {statistics.median(before):.2f} before the freeze, '
          f'{statistics.median(after):.2f} after; each: {", ".join(f"{v:.2f}" for v in before)} | '
          f'{", ".join(f"{v:.2f}" for v in after)}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
