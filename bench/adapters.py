"""msg_adapters speed: decoding and restamping from serialized bytes, per format, against the naive
path (rosbags deserialize to objects, a Python loop, serialize) in the same run.

    ./dev run python bench/adapters.py [--quick]
    ./dev run python bench/adapters.py --ab REF [--quick]
    ./dev run python bench/adapters.py --live [--quick]

evt3 and libcaer_cmp use the real recordings (decoded whole, several passes, each with a fresh
decoder); evt3 also re-cut into messages of 32,768 words, the size a driver sends under a high
event rate (the recording's own messages hold about 660 events, where per-message overhead counts);
libcaer, mono and the dvs / prophesee arrays use synthetic messages of 50,000 events.
Rates are events per second of wall time, best of the timed passes after one untimed warm-up.
Our path starts from the serialized bytes, exactly as the naive one does. The naive path runs on
a slice of the same messages (it is slow), which its rate does not depend on.

``--ab REF`` instead compares the evt3 decode of this checkout's C kernels with that of git
revision REF's ``msg_adapters/_kernels.c``, each built the same way into a temporary folder and
loaded in place of the installed kernels under the same Python decoders, in paired passes of one
run (the decoders' paths, and the kernels alone called message by message): the ratio says
whether a kernel change made event decoding slower. It also gives what asking for trigger edges
costs (``decode_edges``, ``decode_times_edges``) against the plain decode, with this checkout's kernels.

``--live`` instead compares, on the real recordings' EventPacket streams, a live stream's message as
the node takes it in one C call (the decoder's ``step``: decoded, counted on the estimate's grid and
restamped) with the separate calls (``decode_times``, the grid counts in numpy, ``Restamper.restamp``),
in paired passes: microseconds per message, and how many times faster the one call is (median). The
DAVIS346 recording's messages also go rewritten as libcaer and as mono (the same events, time_base and
stamps): no recording of those encodings is shared.
"""

from __future__ import annotations

import argparse
import importlib.machinery
import importlib.util
import subprocess
import tempfile
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from evsync_ros.bag.reader import BagReader
from evsync_ros.core.clock import ClockCorrection
from evsync_testing.realdata import missing, real_data_dir
from evsync_testing.reference import evt3_reference_decode, libcaer_cmp_reference_decode
from msg_adapters.definitions import DVS_EVENT_ARRAY, EVENT_PACKET, PROPHESEE_EVENT_ARRAY, event_typestore
from msg_adapters.registry import decoder_for, restamp

NS = 1_000_000_000
SHIFT = ClockCorrection(offset_ns=1_234_567)


def best_rate(fn, n_events, passes):
    fn()
    best = float('inf')
    for _ in range(passes):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return n_events / best


# --- our paths ----------------------------------------------------------------------------------

def ours_decode(raws, msgtype, xyp=False):
    def run():
        dec = decoder_for(msgtype)
        for raw in raws:
            dec.decode(raw, xyp=xyp)
    return run


def ours_restamp(raws, msgtype):
    def run():
        for raw in raws:
            restamp(raw, msgtype, SHIFT)
    return run


# --- naive paths: objects and Python loops --------------------------------------------------------

def naive_packet_decode(raws, word_loop):
    store = event_typestore()

    def run():
        for raw in raws:
            msg: Any = store.deserialize_cdr(raw, EVENT_PACKET)
            word_loop(msg)
    return run


def naive_packet_restamp(raws):
    store = event_typestore()

    def run():
        for raw in raws:
            msg: Any = store.deserialize_cdr(raw, EVENT_PACKET)
            t = SHIFT.apply_one(msg.header.stamp.sec * NS + msg.header.stamp.nanosec)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t, NS)
            if msg.encoding != 'evt3':
                msg.time_base = SHIFT.apply_one(msg.time_base)
            store.serialize_cdr(msg, EVENT_PACKET)
    return run


def naive_array_decode(raws, msgtype):
    store = event_typestore()

    def run():
        for raw in raws:
            msg: Any = store.deserialize_cdr(raw, msgtype)
            [e.ts.sec * NS + e.ts.nanosec for e in msg.events]
    return run


def naive_array_restamp(raws, msgtype):
    store = event_typestore()

    def run():
        for raw in raws:
            msg: Any = store.deserialize_cdr(raw, msgtype)
            for e in msg.events:
                e.ts.sec, e.ts.nanosec = divmod(SHIFT.apply_one(e.ts.sec * NS + e.ts.nanosec), NS)
            store.serialize_cdr(msg, msgtype)
    return run


def mono_loop(msg):
    for w in msg.events.view('<u8').tolist():
        msg.time_base + (w & 0xFFFFFFFF)


def libcaer_loop(msg):
    high, last = msg.time_base, 0
    for w in msg.events.view('<u8').tolist():
        ts = (w >> 32) & 0x7FFFFFFF
        if ts < last:
            high += (1 << 31) * 1000
        high + ts * 1000
        last = ts


# --- inputs -------------------------------------------------------------------------------------

def real(bag):
    root = real_data_dir()
    reason = missing(root, bag)
    if reason:
        raise SystemExit(reason)
    with BagReader(root / bag) as reader:
        return [bytes(raw) for _, _, raw in reader.messages()]


def repacked(raws, words_per_msg):
    """A real EventPacket stream's payloads cut into messages of ``words_per_msg`` 16-bit words,
    as a driver under a high event rate sends them (stamps keep the recording's anchor)."""
    from evsync_testing.messages import packet_bytes
    from msg_adapters.event_packet import parse_event_packet
    views = [parse_event_packet(raw) for raw in raws]
    payload = np.concatenate([v.events for v in views])
    step = 2 * words_per_msg
    return [packet_bytes(views[0].encoding, payload[i:i + step], time_base=views[0].time_base,
                         stamp_ns=views[0].stamp_ns + i, seq=k + 1, width=views[0].width, height=views[0].height)
            for k, i in enumerate(range(0, payload.size, step))]


def synthetic_packets(encoding, n_msgs, per_msg):
    from evsync_testing.messages import libcaer_payload, mono_payload, packet_bytes
    rng = np.random.default_rng(0)
    out = []
    for i in range(n_msgs):
        dt = np.sort(rng.integers(0, 10_000_000, per_msg))
        x, y, p = rng.integers(0, 640, per_msg), rng.integers(0, 480, per_msg), rng.integers(0, 2, per_msg)
        payload = mono_payload(dt, x, y, p) if encoding == 'mono' else libcaer_payload(dt // 1000, x, y, p)
        out.append(packet_bytes(encoding, payload, time_base=(1_700_000_000 + i) * NS, seq=i + 1))
    return out


def synthetic_arrays(msgtype, n_msgs, per_msg):
    from evsync_testing.messages import array_bytes
    rng = np.random.default_rng(0)
    return [array_bytes(msgtype, (1_700_000_000 + i) * NS + np.sort(rng.integers(0, 10_000_000, per_msg)),
                        rng.integers(0, 346, per_msg), rng.integers(0, 260, per_msg), rng.integers(0, 2, per_msg))
            for i in range(n_msgs)]


def count_events(raws, msgtype):
    dec = decoder_for(msgtype)
    return sum(dec.decode(raw)[1].t.size for raw in raws)


# --- A/B: this checkout's kernels against another revision's ---------------------------------------

def built_kernels(source: bytes, folder: Path, name: str) -> ModuleType:
    """A ``_kernels.c`` source built as setup.py builds it, in ``folder``, loaded as ``<name>._kernels``
    (apart from the installed one)."""
    from setuptools import Distribution, Extension
    folder.mkdir()
    path = folder / '_kernels.c'
    path.write_bytes(source)
    dist = Distribution({'name': name, 'ext_modules': [Extension('_kernels', [str(path)], extra_compile_args=['-O3'])]})
    build: Any = dist.get_command_obj('build_ext')
    build.build_lib = build.build_temp = str(folder)
    build.ensure_finalized()
    build.run()
    loader = importlib.machinery.ExtensionFileLoader(f'{name}._kernels', build.get_ext_fullpath('_kernels'))
    spec = importlib.util.spec_from_loader(loader.name, loader)
    assert spec is not None
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def ab_kernels(ref: str, folder: Path) -> tuple[ModuleType, ModuleType]:
    """(``msg_adapters/_kernels.c`` at git revision ``ref``, this checkout's), each built the same way."""
    root = Path(__file__).resolve().parents[1]
    theirs = subprocess.run(['git', 'show', f'{ref}:msg_adapters/_kernels.c'], cwd=root, check=True,
                            capture_output=True).stdout
    ours = (root / 'msg_adapters' / '_kernels.c').read_bytes()
    return built_kernels(theirs, folder / 'a', 'ab_a'), built_kernels(ours, folder / 'b', 'ab_b')


def decode_path(raws, how):
    """A fresh EventPacketDecoder through the stream: ``decode``, ``decode_times``, ``decode_edges`` or
    ``decode_times_edges``."""
    def run():
        dec = decoder_for(EVENT_PACKET)
        call = getattr(dec, how)
        for raw in raws:
            call(raw)
    return run


def paired(a, b, n_events, passes):
    """(best rate of ``a``, best rate of ``b``, median over passes of b's rate / a's): each pass times
    both back to back, in one order then the other, so the host's load falls on both alike."""
    a(), b()
    best_a = best_b = float('inf')
    ratios = []
    for k in range(passes):
        took = {}
        for name, fn in ((('a', a), ('b', b)) if k % 2 == 0 else (('b', b), ('a', a))):
            t0 = time.perf_counter()
            fn()
            took[name] = time.perf_counter() - t0
        best_a, best_b = min(best_a, took['a']), min(best_b, took['b'])
        ratios.append(took['a'] / took['b'])
    return n_events / best_a, n_events / best_b, float(np.median(ratios))


def kernel_path(module, raws, entry):
    """The kernel alone, message after message (state carried): ``evt3_decode`` on each payload, or
    ``evt3_packet_decode`` on each whole message, outputs sized once."""
    from msg_adapters.event_packet import parse_event_packet
    views = [parse_event_packet(raw) for raw in raws]
    payloads = [np.ascontiguousarray(v.events) for v in views]
    width, height = views[0].width, views[0].height
    cap = 12 * max(len(raw) for raw in raws)
    t = np.empty(cap, np.int64)

    def run():
        state, counters = np.array([-1, -1, 0, 0, 0, 0, 0], np.int64), np.zeros(4, np.int64)
        if entry == 'evt3_decode':
            for payload in payloads:
                module.evt3_decode(payload, state, counters, width, height, cap, t, None, None, None)
        else:
            for raw in raws:
                module.evt3_packet_decode(raw, state, counters, width, height, cap, t, None, None, None)
    return run


def ab(ref: str, passes: int) -> None:
    import msg_adapters.evt3 as evt3_module
    from msg_adapters import _kernels as installed
    with tempfile.TemporaryDirectory() as tmp:
        theirs, ours = ab_kernels(ref, Path(tmp))
    inputs = {
        'evt3_sqlite3 (4,157 trigger words)': real('evt3_sqlite3'),
        'evt3_sqlite3 re-cut: 32k words/msg': repacked(real('evt3_sqlite3'), 32768),
        'evk4_hd (no trigger words)': real('evk4_hd'),
    }
    print(f'evt3 decode, this checkout\'s kernels (B) against {ref}\'s (A): best of {passes} paired passes, '
          'and the median of the pairs\' ratios')
    print(f'{"input":36} {"events":>10} {"path":13} {"A M ev/s":>9} {"B M ev/s":>9} {"B / A":>6} {"median":>7}')

    def with_kernels(module, fn):
        def run():
            setattr(evt3_module, '_kernels', module)  # noqa: B010 (the decoders' module global, swapped)
            try:
                fn()
            finally:
                setattr(evt3_module, '_kernels', installed)  # noqa: B010
        return run

    for name, raws in inputs.items():
        n = count_events(raws, EVENT_PACKET)
        for how in ('decode', 'decode_times'):
            fn = decode_path(raws, how)
            a, b, median = paired(with_kernels(theirs, fn), with_kernels(ours, fn), n, passes)
            print(f'{name:36} {n:>10,} {how:13} {a / 1e6:>9.1f} {b / 1e6:>9.1f} {b / a:>6.3f} {median:>7.3f}')
    print(f'\nthe kernels alone, called per message: {ref}\'s (A) and this checkout\'s (B)')
    print(f'{"input":36} {"events":>10} {"kernel":18} {"A M ev/s":>9} {"B M ev/s":>10} {"B / A":>6} {"median":>7}')
    for name, raws in inputs.items():
        n = count_events(raws, EVENT_PACKET)
        for entry in ('evt3_decode', 'evt3_packet_decode'):
            a, b, median = paired(kernel_path(theirs, raws, entry), kernel_path(ours, raws, entry), n, passes)
            print(f'{name:36} {n:>10,} {entry:18} {a / 1e6:>9.1f} {b / 1e6:>10.1f} {b / a:>6.3f} {median:>7.3f}')
    print('\nasking for trigger edges too, this checkout\'s kernels (each against the path without edges)')
    print(f'{"input":36} {"events":>10} {"path":18} {"M ev/s":>9} {"with edges":>10} {"ratio":>6} {"median":>7}')
    for name, raws in inputs.items():
        n = count_events(raws, EVENT_PACKET)
        for plain, edges in (('decode', 'decode_edges'), ('decode_times', 'decode_times_edges')):
            a, b, median = paired(decode_path(raws, plain), decode_path(raws, edges), n, passes)
            print(f'{name:36} {n:>10,} {edges:18} {a / 1e6:>9.1f} {b / 1e6:>10.1f} {b / a:>6.3f} {median:>7.3f}')


def live_paths(raws: list[bytes], grid_ns: int = 100_000) -> tuple[Any, Any]:
    """A live stream's messages the node's two ways, restamped by ``SHIFT`` (the first decoded apart in
    both, as the node takes a stream's first): the separate calls, and the one call."""
    from msg_adapters.registry import Restamper
    counts = np.zeros(1 << 16, np.int32)

    def apart():
        dec, rs = decoder_for(EVENT_PACKET), Restamper(EVENT_PACKET)
        for raw in raws:
            t = dec.decode_times(raw)
            if t.size:
                np.bincount(t // grid_ns - t.min() // grid_ns)
            rs.restamp(raw, SHIFT)

    def one_call():
        dec, rs = decoder_for(EVENT_PACKET), Restamper(EVENT_PACKET)
        dec.decode(raws[0])
        rs.restamp(raws[0], SHIFT)
        for raw in raws[1:]:
            if dec.step(raw, grid_ns=grid_ns, counts=counts, restamper=rs.packets, correction=SHIFT) is None:
                raise AssertionError('a message the one call did not take: the comparison would not be one')
    return apart, one_call


def live(passes: int) -> None:
    from evsync_testing.messages import rewritten
    davis = real('libcaer_cmp_mcap')
    print(f'{"input":34} {"messages":>9} {"apart us":>9} {"one call us":>12} {"apart / one":>12}')
    for name, raws in (('evt3 (real, Prophesee)', real('evt3_sqlite3')), ('libcaer_cmp (real, DAVIS346)', davis),
                       ('libcaer (DAVIS346, rewritten)', rewritten(davis, 'libcaer')),
                       ('mono (DAVIS346, rewritten)', rewritten(davis, 'mono'))):
        a, b, median = paired(*live_paths(raws), len(raws), passes)
        print(f'{name:34} {len(raws):>9,} {1e6 / a:>9.1f} {1e6 / b:>12.1f} {median:>12.3f}')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--quick', action='store_true', help='fewer messages and passes (a smoke run)')
    parser.add_argument('--ab', metavar='REF', help="only the A/B of evt3 decoding against git revision REF's kernels")
    parser.add_argument('--live', action='store_true', help="only a live stream's message: one C call against "
                        'the separate calls')
    args = parser.parse_args()
    passes = 2 if args.quick else 5
    if args.live:
        live(4 if args.quick else 15)
        return
    if args.ab:
        ab(args.ab, 4 if args.quick else 25)
        return
    n_syn = 4 if args.quick else 40

    evt3_ref = evt3_reference_decode
    cmp_ref = libcaer_cmp_reference_decode
    inputs = {
        'evt3 (real, Prophesee)': (EVENT_PACKET, real('evt3_sqlite3'),
                                   lambda m: evt3_ref([m.events], m.width, m.height)),
        'evt3 (real, re-cut: 32k words/msg)': (EVENT_PACKET, repacked(real('evt3_sqlite3'), 32768),
                                               lambda m: evt3_ref([m.events], m.width, m.height)),
        'libcaer_cmp (real, DAVIS346)': (EVENT_PACKET, real('libcaer_cmp_mcap'),
                                         lambda m: cmp_ref([(m.events, m.time_base)], m.width, m.height)),
        'libcaer (synthetic)': (EVENT_PACKET, synthetic_packets('libcaer', n_syn, 50_000), libcaer_loop),
        'mono (synthetic)': (EVENT_PACKET, synthetic_packets('mono', n_syn, 50_000), mono_loop),
        'dvs EventArray (synthetic)': (DVS_EVENT_ARRAY, synthetic_arrays(DVS_EVENT_ARRAY, n_syn, 50_000), None),
        'prophesee EventArray (synthetic)': (PROPHESEE_EVENT_ARRAY,
                                             synthetic_arrays(PROPHESEE_EVENT_ARRAY, n_syn, 50_000), None),
    }
    print(f'{"format":34} {"events":>10} {"what":8} {"ours M ev/s":>12} {"naive M ev/s":>13} {"x naive":>8}')
    for name, (msgtype, raws, loop) in inputs.items():
        n = count_events(raws, msgtype)
        naive_raws, naive_n = raws, n
        while naive_n > 120_000 and len(naive_raws) > 1:  # the naive path on a slice
            naive_raws = naive_raws[: len(naive_raws) // 2]
            naive_n = count_events(naive_raws, msgtype)
        is_array = msgtype != EVENT_PACKET
        rows = [
            ('decode', ours_decode(raws, msgtype),
             naive_array_decode(naive_raws, msgtype) if is_array else naive_packet_decode(naive_raws, loop)),
            ('restamp', ours_restamp(raws, msgtype),
             naive_array_restamp(naive_raws, msgtype) if is_array else naive_packet_restamp(naive_raws)),
        ]
        for what, ours, naive in rows:
            r_ours = best_rate(ours, n, passes)
            r_naive = best_rate(naive, naive_n, 1 if args.quick else 2)
            print(f'{name:34} {n:>10,} {what:8} {r_ours / 1e6:>12.1f} {r_naive / 1e6:>13.2f} {r_ours / r_naive:>8.0f}')


if __name__ == '__main__':
    main()
