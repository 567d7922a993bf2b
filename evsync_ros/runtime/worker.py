"""The estimator's worker process (``runtime.runner.InProcess``): ``python -m evsync_ros.runtime.worker
PARENT_PID NICE``. It reads pickled calls on stdin and answers each on stdout with (True, result) or
(False, what it raised), until stdin ends. It dies with its parent however the parent dies (Linux
prctl). Nothing imports this module, so that ``-m`` loads it once."""

from __future__ import annotations

import os
import pickle
import signal
import sys

from evsync_ros.core.errors import StreamError
from evsync_ros.lifetime import die_with_parent
from evsync_ros.runtime.runner import WorkerDied, receive, send


def serve(parent: int, nice: int) -> int:
    """Answer calls until stdin ends (0), or 1 when ``parent`` is gone already. Its own prints go to
    stderr: stdout is the answers'."""
    if not die_with_parent(signal.SIGKILL, parent=parent):  # the parent was gone already
        return 1
    if nice:
        os.nice(nice)
    answers = os.fdopen(os.dup(1), 'wb')
    os.dup2(2, 1)
    calls = sys.stdin.buffer
    send(answers, os.getpid())
    while True:
        try:
            fn, args = receive(calls)
        except WorkerDied:
            return 0
        try:
            reply = (True, fn(*args))
        except Exception as exc:  # noqa: BLE001 (raised again by run, in the node)
            reply = (False, exc)
        try:
            send(answers, reply)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:
            send(answers, (False, StreamError(f'{fn.__name__}: its result or error does not pickle: {exc!r}')))


if __name__ == '__main__':
    sys.exit(serve(int(sys.argv[1]), int(sys.argv[2])))
