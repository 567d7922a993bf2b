"""A progress bar on standard error for long bag runs; silent when stderr is not a terminal."""

from __future__ import annotations

import sys
import time
from typing import TextIO

SPINNER = '|/-\\'


class Progress:
    """``progress(done, total)`` redraws ``label [#####     ] 42% 1,234/2,938 messages, 3 s`` at most
    every ``every_s``.

    The bar's total is the one known as a pass over the bag begins: a total that grows mid-run is a
    pass more (the estimate reads the drifting cameras a second time, which only the first pass can
    tell), so the bar starts again for it, ``pass 2``, rather than fall back. ``exact=False``: the
    totals are guesses (a stretch of a bag, whose messages are counted as they come): a spinner and
    the count, no percentage."""

    def __init__(self, label: str, *, stream: TextIO | None = None, force: bool = False, every_s: float = 0.2,
                 exact: bool = True) -> None:
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = force or self.stream.isatty()
        self.every_s = every_s
        self.exact = exact
        self._last = 0.0
        self._t0 = time.monotonic()
        self._drawn = False
        self._total: int | None = None
        self._base = 0
        """What the passes before this one counted."""
        self._pass = 1
        self._turn = 0
        self._width = 0
        """The longest line drawn: a shorter one is padded over it."""

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled:
            return
        if self._total is not None and total > self._total:  # another pass begins
            self._base, self._pass = self._total, self._pass + 1
        self._total = total
        now = time.monotonic()
        if done < total and now - self._last < self.every_s:
            return
        self._last = now
        label = self.label if self._pass == 1 else f'{self.label}, pass {self._pass}'
        mine, of = max(done - self._base, 0), total - self._base
        if self.exact:
            frac = min(1.0, mine / of) if of > 0 else 1.0
            line = f'{label} [{"#" * int(frac * 30):<30}] {frac:4.0%} {mine:,}/{of:,} messages'
        else:
            self._turn += 1
            line = f'{label} {SPINNER[self._turn % len(SPINNER)]} {mine:,} messages'
        line = f'{line}, {now - self._t0:.0f} s'
        self._width = max(self._width, len(line))
        self.stream.write(f'\r{line:<{self._width}}')
        self.stream.flush()
        self._drawn = True

    def close(self) -> None:
        if self.enabled and self._drawn:
            self.stream.write('\n')
            self.stream.flush()
            self._drawn = False
