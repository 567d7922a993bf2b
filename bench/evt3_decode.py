"""evt3 time decoding speed: the vectorised decoder against the plain word-by-word reference
decoder of the tests, in one run, on the real Prophesee recording re-cut into messages of
several sizes (steady state: each size decoded three times, the first pass not timed).

    ./dev run python bench/evt3_decode.py
"""

from __future__ import annotations

import importlib.util
import time

import numpy as np

from _common import REPO, real_data_dir
from evsync_ros.bagio import BagReader
from msg_adapters.event_packet import parse_event_packet
from msg_adapters.evt3 import Evt3Decoder


def _reference_decoder():
    spec = importlib.util.spec_from_file_location('test_evt3', REPO / 'test' / 'test_evt3.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.reference_decode


def _rate(fn, msgs, repeats):
    fn(msgs)  # warm-up: allocator and caches in steady state
    t0 = time.perf_counter()
    n = sum(fn(msgs) for _ in range(repeats))
    return n / (time.perf_counter() - t0)


def main() -> None:
    with BagReader(real_data_dir() / 'evt3_sqlite3') as reader:
        packets = [parse_event_packet(raw) for _, _, raw in reader.messages()]
    payload = np.concatenate([p.events for p in packets])

    def numpy_times(msgs):
        dec = Evt3Decoder(width=640, height=480)
        return sum(dec.decode(m).t.size for m in msgs)

    def numpy_txyp(msgs):
        dec = Evt3Decoder(width=640, height=480)
        return sum(dec.decode(m, xyp=True).t.size for m in msgs)

    reference = _reference_decoder()
    baseline = _rate(lambda msgs: len(reference(msgs, 640, 480)), [p.events for p in packets], 1)
    print(f'evt3 recording: {payload.size // 2:,} words, {numpy_times([payload]):,} events')
    print(f'plain word-by-word reference decoder (baseline): {baseline / 1e6:.2f} M events/s\n')
    print(f'{"words/message":>13} {"times M ev/s":>13} {"x baseline":>10} {"t,x,y,p M ev/s":>15} {"x baseline":>10}')
    for words in (664 * 3, 4096, 32768, 262144):
        step = 2 * words
        msgs = [payload[i:i + step] for i in range(0, payload.size, step)]
        r_t = _rate(numpy_times, msgs, 3)
        r_all = _rate(numpy_txyp, msgs, 3)
        print(f'{words:>13,} {r_t / 1e6:>13.2f} {r_t / baseline:>10.1f} {r_all / 1e6:>15.2f} {r_all / baseline:>10.1f}')


if __name__ == '__main__':
    main()
