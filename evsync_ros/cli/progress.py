"""A progress bar on standard error for long bag runs; silent when stderr is not a terminal."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """``progress(done, total)`` redraws ``label [#####     ] 42%`` at most every ``every_s``."""

    def __init__(self, label: str, *, stream: TextIO | None = None, force: bool = False, every_s: float = 0.2) -> None:
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = force or self.stream.isatty()
        self.every_s = every_s
        self._last = 0.0
        self._t0 = time.monotonic()
        self._drawn = False

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if done < total and now - self._last < self.every_s:
            return
        self._last = now
        frac = min(1.0, done / total) if total else 1.0
        bar = '#' * int(frac * 30)
        self.stream.write(f'\r{self.label} [{bar:<30}] {frac:4.0%} {done:,}/{total:,} messages, {now - self._t0:.0f} s')
        self.stream.flush()
        self._drawn = True

    def close(self) -> None:
        if self.enabled and self._drawn:
            self.stream.write('\n')
            self.stream.flush()
            self._drawn = False
