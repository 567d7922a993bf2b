"""A helper process's tie to the process that started it: the estimator's worker, a camera process,
a bag job and a pipeline's child each end when their parent does, however it ends."""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal

__all__ = ['die_with_parent']

PR_SET_PDEATHSIG = 1
"""Linux prctl: the signal this process gets when its parent dies."""


def die_with_parent(signum: int = signal.SIGTERM, *, parent: int | None = None) -> bool:
    """Have this process sent ``signum`` when its parent dies (Linux prctl; nothing elsewhere).
    ``parent``: the process id the caller expects as its parent; False when that one has gone
    already (it died before the call took effect, so no signal will come)."""
    with contextlib.suppress(Exception):  # not Linux, or no libc by that name: nothing to tie
        ctypes.CDLL('libc.so.6', use_errno=True).prctl(PR_SET_PDEATHSIG, signum)
    return parent is None or os.getppid() == parent
