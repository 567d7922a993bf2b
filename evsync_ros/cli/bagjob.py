"""One bag of a many-bag ``evsync estimate`` or ``restamp`` (``cli.batch``): ``python -m
evsync_ros.cli.bagjob RESULT.json PARENT_PID``, the command's parsed arguments pickled on stdin.
It runs the one-bag command (``args.one``) as ``evsync`` would, and writes what it did to
RESULT.json (renamed into place: a result there is whole). SIGTERM, and its parent's death (Linux
prctl), end it as Ctrl-C ends ``evsync``: its partial output removed. Nothing imports this module,
so that ``-m`` loads it once."""

from __future__ import annotations

import argparse
import json
import pickle
import signal
import sys
from pathlib import Path
from types import FrameType
from typing import IO

from evsync_ros.cli.batch import CLOSED_PIPE, INTERRUPTED, Ran
from evsync_ros.cli.command import quiet_stdout
from evsync_ros.errors import EXPECTED_ERRORS
from evsync_ros.lifetime import die_with_parent


def _terminated(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


def run(stream: IO[bytes]) -> tuple[Ran, str | None]:
    """The one-bag command's result, and its error's message (None when there was none); its
    arguments pickled on ``stream`` (their loading imports the command: interrupted too)."""
    try:
        args: argparse.Namespace = pickle.load(stream)
        return args.one(args), None
    except EXPECTED_ERRORS as exc:
        print(f'evsync: error: {exc}', file=sys.stderr)
        return Ran(status=2), str(exc)
    except KeyboardInterrupt:
        print('evsync: interrupted; nothing partial was left behind', file=sys.stderr)
        return Ran(status=INTERRUPTED), None
    except BrokenPipeError:  # the command's standard output, closed by its reader: the command ends
        quiet_stdout()
        return Ran(status=CLOSED_PIPE), None


def main(result: Path, parent: int) -> int:
    signal.signal(signal.SIGTERM, _terminated)
    if not die_with_parent(signal.SIGTERM, parent=parent):  # the parent was gone already
        return INTERRUPTED
    ran, error = run(sys.stdin.buffer)
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        quiet_stdout()
        ran = Ran(status=CLOSED_PIPE)
    partial = result.with_name(f'.{result.name}.partial')
    partial.write_text(json.dumps({'ran': ran.as_json(), 'error': error}))
    partial.rename(result)
    return ran.status


if __name__ == '__main__':
    sys.exit(main(Path(sys.argv[1]), int(sys.argv[2])))
