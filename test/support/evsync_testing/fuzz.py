"""What the fuzz tests share: hypothesis settings, a guard against hangs, message strategies and mutations.

``EVSYNC_FUZZ_EXAMPLES`` sets how many examples each property tries (default 120; ``bench/faults.py``
asks for more).
"""

from __future__ import annotations

import contextlib
import os
import signal
import struct

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from msg_adapters.event_array import encode_event_array
from msg_adapters.event_packet import ENCODINGS, encode_event_packet
from msg_adapters.evt3 import encode_evt3

EXAMPLES = int(os.environ.get('EVSYNC_FUZZ_EXAMPLES', '120'))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=not os.environ.get('EVSYNC_FUZZ_RANDOM'),
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])
"""Deterministic by default (the suite must not flake); EVSYNC_FUZZ_RANDOM=1 explores afresh."""
HEAVY = settings(FUZZ, max_examples=max(10, EXAMPLES // 4))
"""For properties whose every example runs an estimator."""
S = 1_000_000_000


@contextlib.contextmanager
def no_hang(seconds: float = 10.0):
    """Fail (TimeoutError) if the block runs longer than ``seconds``: a hang is a defect, not a wait."""
    def alarm(signum, frame):
        raise TimeoutError(f'no result after {seconds} s')

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


# -- payloads and messages --------------------------------------------------------------------------

def _words(draw, codes: range, max_words: int = 600) -> bytes:
    n = draw(st.integers(0, max_words))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    code = rng.choice(np.array(list(codes)), n).astype(np.uint16)
    return ((code << 12) | rng.integers(0, 4096, n).astype(np.uint16)).astype('<u2').tobytes()


@st.composite
def payloads(draw, encoding: str) -> bytes:
    """Plausible and implausible payload bytes for an EventPacket encoding."""
    kind = draw(st.sampled_from(['valid', 'words', 'bytes']))
    if kind == 'bytes':
        return draw(st.binary(max_size=2048))
    if encoding in ('evt3', 'libcaer_cmp') and kind == 'words':
        return _words(draw, range(16))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(0, 300))
    t = np.sort(rng.integers(0, draw(st.sampled_from([1, 1000, 10**6, 2**24 + 5, 2**31 + 7])), n))
    x, y, p = rng.integers(0, 2048, n), rng.integers(0, 2048, n), rng.integers(0, 2, n)
    if encoding == 'evt3':
        return encode_evt3(t, x, y, p)
    if encoding == 'libcaer_cmp':
        return _words(draw, range(6))
    if encoding == 'libcaer':
        data = (x.astype(np.uint32) << 17) | (y.astype(np.uint32) << 2) | (p.astype(np.uint32) << 1)
        return np.stack([data, (t & 0xFFFFFFFF).astype(np.uint32)], axis=1).astype('<u4').tobytes()
    words = (p.astype(np.uint64) << 63) | (y.astype(np.uint64) << 48) | (x.astype(np.uint64) << 32) \
        | (t & 0xFFFFFFFF).astype(np.uint64)
    return words.astype('<u8').tobytes()


u32 = st.integers(0, 2**32 - 1)
u64 = st.integers(0, 2**64 - 1)
stamps = st.one_of(st.integers(0, 2**31 - 1).map(lambda s: s * S), st.integers(-(2**31) * S, (2**31 - 1) * S))


@st.composite
def event_packets(draw, encoding: str | None = None) -> bytes:
    """A serialized EventPacket: any encoding (or an unknown one), any geometry, any time base."""
    encoding = encoding or draw(st.one_of(st.sampled_from(ENCODINGS), st.text(max_size=12)))
    return encode_event_packet(
        stamp_ns=draw(stamps), frame_id=draw(st.text(max_size=20)),
        width=draw(st.one_of(st.sampled_from([0, 1, 346, 640, 1280, 2048]), u32)),
        height=draw(st.one_of(st.sampled_from([0, 1, 260, 480, 720, 2048]), u32)),
        seq=draw(u64), time_base=draw(st.one_of(st.just(0), st.integers(0, 2**62), u64)),
        encoding=encoding, payload=draw(payloads(encoding if encoding in ENCODINGS else 'evt3')))


@st.composite
def event_arrays(draw) -> bytes:
    """A serialized dvs / prophesee EventArray (same bytes) with any event times ROS time can hold."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(0, 300))
    base = draw(st.integers(-(2**31) * S + 10 * S, (2**31 - 11) * S))
    t = base + np.sort(rng.integers(0, draw(st.sampled_from([1, 10**6, 10 * S])), n))
    if draw(st.booleans()):
        rng.shuffle(t)
    return encode_event_array(stamp_ns=draw(stamps), frame_id=draw(st.text(max_size=20)),
                              width=draw(u32), height=draw(u32), t=t, x=rng.integers(0, 65536, n),
                              y=rng.integers(0, 65536, n), p=rng.integers(0, 2, n))


@st.composite
def mutated(draw, messages: st.SearchStrategy[bytes]) -> bytes:
    """A message with a few of: bytes flipped, cut short, lengthened, a 32-bit field made absurd."""
    raw = bytearray(draw(messages))
    for _ in range(draw(st.integers(1, 3))):
        what = draw(st.sampled_from(['flip', 'truncate', 'insert', 'u32', 'append', 'empty']))
        at = draw(st.integers(0, max(0, len(raw) - 1)))
        if what == 'flip' and raw:
            raw[at] ^= draw(st.integers(1, 255))
        elif what == 'truncate':
            del raw[at:]
        elif what == 'insert':
            raw[at:at] = draw(st.binary(min_size=1, max_size=16))
        elif what == 'u32' and len(raw) >= 8:
            pos = 4 + 4 * draw(st.integers(0, (len(raw) - 8) // 4))
            struct.pack_into('<I', raw, pos, draw(st.sampled_from([0, 1, 2**31 - 1, 2**31, 2**32 - 1,
                                                                  len(raw), len(raw) + 1])))
        elif what == 'append':
            raw += draw(st.binary(min_size=1, max_size=64))
        elif what == 'empty':
            raw = bytearray(draw(st.sampled_from([b'', b'\x00\x01\x00\x00', b'\x00\x01\x00\x00' + bytes(12)])))
    return bytes(raw)
