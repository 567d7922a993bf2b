"""A synthetic evt3 camera that never ends: one cycle of payloads (and a burst's) encoded once and sent
again and again, its TIME_HIGH words moved on by a cycle's sensor time each time, so that sensor time
runs on without a break and wraps every 16.8 s as a real sensor's does. The soak's input
(``bench/soak.py``)."""

from __future__ import annotations

import numpy as np

from msg_adapters.evt3 import encode_evt3

MESSAGE_NS = 10_000_000
"""The default message length; ``Cycle(message_ns=1_000_000)`` sends the drivers' 1 ms packets."""
CYCLE_NS = 10_240_000_000
"""10.24 s: a whole number of TIME_HIGH units (4096 us) and of 1 ms or 10 ms messages."""
CYCLE_HIGH_UNITS = CYCLE_NS // 1000 // 4096
CYCLE_MESSAGES = CYCLE_NS // MESSAGE_NS
"""Messages per cycle at the default message length."""
BURST_EVERY = 6
"""Cycles between bursts (61.44 s)."""
BURST_AT_NS = 4_000_000_000
BURST_NS = 500_000_000
"""The burst replaces the messages of [BURST_AT_NS, BURST_AT_NS + BURST_NS) of its cycle."""
BURST_MESSAGES = BURST_NS // MESSAGE_NS
BURST_AT = BURST_AT_NS // MESSAGE_NS
"""... messages BURST_AT .. BURST_AT + BURST_MESSAGES at the default message length."""
BURST_FACTOR = 10


class Cycle:
    """One cycle of evt3 payloads (and the burst's), with where their TIME_HIGH words are."""

    def __init__(self, rate_per_camera: float, seed: int = 0, *, message_ns: int = MESSAGE_NS) -> None:
        if message_ns % 1_000_000 or CYCLE_NS % message_ns or BURST_NS % message_ns:
            raise ValueError(f'message_ns {message_ns} must be whole ms dividing 0.5 s')
        self.message_ns = message_ns
        self.per_cycle = CYCLE_NS // message_ns
        """Messages per cycle."""
        self.burst_at, self.burst_messages = BURST_AT_NS // message_ns, BURST_NS // message_ns
        rng = np.random.default_rng(seed)
        ms = CYCLE_NS // 1_000_000
        step = message_ns // 1_000_000
        envelope = np.convolve(rng.random(ms) ** 4, np.ones(20) / 20, mode='same')
        envelope /= envelope.mean()

        def payloads(per_ms: np.ndarray, first: int, count: int) -> list[tuple[np.ndarray, np.ndarray, int]]:
            out: list[tuple[np.ndarray, np.ndarray, int]] = []
            for k in range(first, first + count):
                n = rng.poisson(per_ms[k * step:(k + 1) * step])
                t_us = (np.repeat(np.arange(k * step, (k + 1) * step, dtype=np.int64) * 1000, n)
                        + rng.integers(0, 1000, int(n.sum())))
                t_us.sort()
                n_ev = t_us.size
                x, y, p = rng.integers(0, 1280, n_ev), rng.integers(0, 720, n_ev), rng.integers(0, 2, n_ev)
                words = np.frombuffer(encode_evt3(t_us, x, y, p), '<u2').copy()
                out.append((words, np.flatnonzero((words >> 12) == 0x8), t_us.size))
            return out

        per_ms = rate_per_camera / 1000 * envelope
        self.messages = payloads(per_ms, 0, self.per_cycle)
        self.burst = payloads(per_ms * BURST_FACTOR, self.burst_at, self.burst_messages)

    def without_bursts(self) -> None:
        """Every cycle as the first: the burst's messages are the cycle's own."""
        self.burst = [self.messages[k] for k in range(self.burst_at, self.burst_at + self.burst_messages)]

    def _entry(self, cycle: int, k: int) -> tuple[np.ndarray, np.ndarray, int]:
        """(words, where the TIME_HIGH words are, events) of message k of cycle ``cycle``."""
        burst = cycle % BURST_EVERY == BURST_EVERY - 1 and self.burst_at <= k < self.burst_at + self.burst_messages
        return self.burst[k - self.burst_at] if burst else self.messages[k]

    def events(self, cycle: int, k: int) -> int:
        return self._entry(cycle, k)[2]

    def payload(self, cycle: int, k: int) -> bytes:
        """Message k of cycle ``cycle``: its sensor time moved on by ``cycle`` cycles."""
        words, high, _ = self._entry(cycle, k)
        shift = cycle * CYCLE_HIGH_UNITS % 4096
        if not shift:
            return words.tobytes()
        moved = words.copy()
        moved[high] = 0x8000 | ((words[high] & 0xFFF) + shift) & 0xFFF
        return moved.tobytes()
