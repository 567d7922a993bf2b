"""The evsync command line: a table of commands, each a module of its own (its arguments and its run),
and how every one of them ends (command.Exit; README, "Exit statuses")."""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
import traceback
from collections.abc import Iterator, Mapping, Sequence
from types import FrameType

from evsync_ros import __version__
from evsync_ros.cli import demo, estimate, play, plotjuggler, report, restamp, simulate, verify
from evsync_ros.cli.argv import positionals_last
from evsync_ros.cli.command import Command, Exit, quiet_stdout
from evsync_ros.errors import EXPECTED_ERRORS

__all__ = ['COMMANDS', 'INTERNAL_ERROR', 'build_parser', 'main', 'parse']

DESCRIPTION = 'The evsync command line: synchronise event cameras in software.'

COMMANDS: Mapping[str, Command] = {c.name: c for c in (demo.COMMAND, simulate.COMMAND, estimate.COMMAND,
                                                        restamp.COMMAND, report.COMMAND, verify.COMMAND,
                                                        plotjuggler.COMMAND, play.COMMAND)}
"""Every ``evsync`` command by name, in the order ``evsync --help`` lists them."""

INTERNAL_ERROR = Exit.INTERNAL
"""The exit status of a command that met a defect of evsync_ros (sysexits' EX_SOFTWARE)."""


def build_parser() -> argparse.ArgumentParser:
    """``evsync`` itself: --help, --version and the commands, each with its help line (a command's own
    options are its parser's, ``Command.parser``)."""
    parser = argparse.ArgumentParser(prog='evsync', description=DESCRIPTION)
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    sub = parser.add_subparsers(dest='command', required=True)
    for command in COMMANDS.values():
        sub.add_parser(command.name, help=command.help, add_help=False)
    return parser


def parse(argv: Sequence[str]) -> tuple[Command, argparse.Namespace]:
    """The command ``argv`` names and its arguments (options before or after its positionals,
    ``argv.positionals_last``); SystemExit as argparse exits (--help, --version, a usage error)."""
    command = COMMANDS.get(argv[0]) if argv else None
    if command is None:
        parser = build_parser()
        parser.parse_args(argv)  # --help, --version, or the error naming the commands: exits
        parser.error('the command comes first: evsync COMMAND [options]')  # (evsync -- estimate BAG)
    words, extra = command.split(list(argv[1:]))
    parser, spec = command.parser()
    args = parser.parse_args(positionals_last(spec, words, least=command.least(words)))
    for key, value in extra.items():
        setattr(args, key, value)
    return command, args


def main(argv: Sequence[str] | None = None) -> int:
    """Run one ``evsync`` command; its exit status (``Exit``)."""
    try:
        command, args = parse(list(sys.argv[1:] if argv is None else argv))
    except KeyboardInterrupt:  # while a command's modules load (rclpy's take a second)
        return Exit.INTERRUPTED
    with _terminated_as_interrupt():
        try:
            status = int(command.run(args))
            sys.stdout.flush()  # a reader gone is met here, not at exit
            return status
        except EXPECTED_ERRORS as exc:
            print(f'evsync: error: {exc}', file=sys.stderr)
            return Exit.ERROR
        except KeyboardInterrupt:
            if command.interrupted:
                print(command.interrupted, file=sys.stderr)
            return Exit.INTERRUPTED
        except BrokenPipeError:  # its reader has gone (| head): nothing more to say, to anyone
            quiet_stdout()
            return Exit.CLOSED_PIPE
        except Exception:  # noqa: BLE001 (a defect: Python's own status for it, 1, would read as "not accepted")
            traceback.print_exc()
            print('evsync: internal error: a defect of evsync_ros, not of the input (please report it with the '
                  'traceback above)', file=sys.stderr)
            return Exit.INTERNAL


@contextlib.contextmanager
def _terminated_as_interrupt() -> Iterator[None]:
    """SIGTERM as Ctrl-C while a command runs (it unwinds, its partial outputs removed, rather than vanish)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _terminated(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


if __name__ == '__main__':
    sys.exit(main())
