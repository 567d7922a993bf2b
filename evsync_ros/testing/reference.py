"""Plain-Python decoders written straight from the format descriptions: the oracle the tests check
the C word loops against, and the naive baseline of ``bench/adapters.py``. Slow on purpose: one
Python step per word, no state shared with the decoders under test."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

Event = tuple[int, int, int, int]
"""(time ns, x, y, polarity)."""


def evt3_reference_decode(payloads: Iterable[bytes], width: int, height: int) -> list[Event]:
    """Word by word, as the evt3 format describes; state carried across payloads."""
    out: list[Event] = []
    th = tl = -1
    wraps = y = base_x = pol = 0
    valid = False
    for payload in payloads:
        for w in np.frombuffer(bytes(payload), dtype='<u2').tolist():
            typ, v = w >> 12, w & 0xFFF
            if typ == 0x8:
                if th >= 0 and th - v > 10:
                    wraps += 1
                th = v
            elif typ == 0x6:
                tl = v
                valid = valid or th >= 0
            elif typ == 0x0:
                y = v & 0x7FF
            elif typ == 0x3:
                base_x, pol = v & 0x7FF, v >> 11
            elif typ in (0x2, 0x4, 0x5):
                t = ((wraps << 24) | (th << 12) | tl) * 1000
                if typ == 0x2:
                    hits = [(v & 0x7FF, v >> 11)]
                else:
                    size = 12 if typ == 0x4 else 8
                    hits = [(base_x + i, pol) for i in range(size) if v >> i & 1]
                    base_x += size
                if valid:
                    out += [(t, x, y, p) for x, p in hits if x < width and y < height]
    return out


def libcaer_cmp_reference_decode(packets: Iterable[tuple[bytes, int]], width: int, height: int) -> list[Event]:
    """Word by word, as the libcaer_cmp format describes: (t, x, y, p) per event."""
    out: list[Event] = []
    x = base_y = pol = 0
    for payload, time_base in packets:
        high = low = 0
        for w in np.frombuffer(bytes(payload), dtype='<u2').tolist():
            code, v = w >> 12, w & 0xFFF
            t = ((high << 12) | low) * 1000 + time_base
            if code == 0:
                high = v
            elif code == 1:
                low = v
            elif code == 2:
                x = v & 0x7FF
            elif code == 3:
                if x < width and (v & 0x7FF) < height:
                    out.append((t, x, v & 0x7FF, v >> 11))
            elif code == 4:
                base_y, pol = v & 0x7FF, v >> 11
            elif code == 5:
                out += [(t, x, base_y + i, pol) for i in range(8) if v >> i & 1 and x < width and base_y + i < height]
                base_y += 8
    return out
