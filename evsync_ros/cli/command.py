"""One ``evsync`` command: its arguments as it declares them, what it runs, and the exit statuses every
command ends with (README, "Exit statuses")."""

from __future__ import annotations

import argparse
import contextlib
import enum
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from evsync_ros.cli.argv import OPTIONAL_NUMBER, Spec
from evsync_ros.errors import EvsyncError

__all__ = ['Arguments', 'Command', 'Exit', 'output_file', 'quiet_stdout']


class Exit(enum.IntEnum):
    """How a command ends: its exit status."""

    DONE = 0
    INCOMPLETE = 1
    """Done, with something not accepted, nothing to synchronise, or messages written unchanged
    (``evsync play``: a clear error about the bag or a value)."""
    ERROR = 2
    """A clear error, its message on standard error (a usage error: argparse's, also 2)."""
    INTERNAL = 70
    """A defect of evsync_ros, its traceback on standard error (sysexits' EX_SOFTWARE)."""
    INTERRUPTED = 130
    """Ctrl-C or SIGTERM (128 + SIGINT, as a shell reports a command Ctrl-C ends); nothing partial is left."""
    CLOSED_PIPE = 141
    """Standard output closed by its reader (``| head``): 128 + SIGPIPE, what a shell reports for any
    command a closed pipe ends (cat, grep, yes), so that a pipeline sees evsync end as it sees them."""


_NO_WORDS = frozenset({'store_true', 'store_false', 'store_const', 'append_const', 'count', 'help', 'version'})
"""The argparse actions whose option takes no word after it."""


class Arguments:
    """A command's parser with its arguments added through ``add``, each one's arity kept: what
    ``argv.positionals_last`` needs, which argparse keeps no public record of."""

    def __init__(self, parser: argparse.ArgumentParser) -> None:
        self.parser = parser
        self._positionals: list[int | str | None] = []
        self._many: set[str] = set()
        self._takes: dict[str, int] = {}

    def add(self, *names: str, group: Any = None, **kwargs: Any) -> None:
        """``parser.add_argument(*names, **kwargs)`` (on ``group``, a mutually exclusive group of
        ``exclusive``, when given), its arity noted."""
        (group or self.parser).add_argument(*names, **kwargs)
        nargs = kwargs.get('nargs')
        if not names[0].startswith('-'):
            self._positionals.append(nargs)
        elif kwargs.get('action') in _NO_WORDS:
            self._takes.update(dict.fromkeys(names, 0))
        elif nargs in ('+', '*'):
            self._many.update(names)
        else:
            takes = nargs if isinstance(nargs, int) else OPTIONAL_NUMBER if nargs == '?' else 1
            self._takes.update(dict.fromkeys(names, takes))

    def exclusive(self) -> Any:
        """A mutually exclusive group for ``add(..., group=)``."""
        return self.parser.add_mutually_exclusive_group()

    @property
    def spec(self) -> Spec:
        return Spec(positionals=tuple(self._positionals), many=frozenset(self._many), takes=dict(self._takes))


def _no_least(argv: Sequence[str]) -> int | None:
    return None


def _all_words(argv: list[str]) -> tuple[list[str], dict[str, Any]]:
    return argv, {}


@dataclass(frozen=True)
class Command:
    """One row of ``main.COMMANDS``: a command's name and help line, the function that declares its
    arguments, the one that runs it (an exit status from parsed arguments), and what its parser
    says besides. ``least``: the fewest positionals of a command line (None: one per positional).
    ``split``: the words its parser takes (``evsync play``: those before --ros-args)."""

    name: str
    help: str
    declare: Callable[[Arguments], None]
    run: Callable[[argparse.Namespace], int]
    usage: str | None = None
    description: str | None = None
    epilog: str | None = None
    least: Callable[[Sequence[str]], int | None] = _no_least
    split: Callable[[list[str]], tuple[list[str], dict[str, Any]]] = _all_words
    """The words its parser takes, and what it sets on the parsed arguments of the others."""
    interrupted: str = 'evsync: interrupted; nothing partial was left behind'
    """What is said when Ctrl-C or SIGTERM ends it."""
    defaults: Mapping[str, Any] = field(default_factory=dict)
    """Set on its parsed arguments besides the options (``one``: the one-bag run of a command of
    several bags, ``cli.batch``)."""

    def parser(self) -> tuple[argparse.ArgumentParser, Spec]:
        """Its parser, ``evsync NAME``, and what ``argv.positionals_last`` needs of it."""
        parser = argparse.ArgumentParser(prog=f'evsync {self.name}', usage=self.usage, description=self.description,
                                         epilog=self.epilog)
        arguments = Arguments(parser)
        self.declare(arguments)
        parser.set_defaults(**self.defaults)
        return parser, arguments.spec


def quiet_stdout() -> None:
    """Standard output onto /dev/null once its reader has gone (``Exit.CLOSED_PIPE``), so that what is
    still buffered, flushed at exit, goes nowhere rather than raise again (Python's "Note on SIGPIPE")."""
    with contextlib.suppress(OSError, ValueError, AttributeError):
        fd = sys.stdout.fileno()
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)


def output_file(path: str | None, *, option: str) -> None:
    """A file a command will write (``--plot``, ``-o``): EvsyncError naming it when it is a folder or its
    folder is not one, before anything is read or estimated (the write would fail after all of that)."""
    if not path:
        return
    folder = Path(path).parent
    if Path(path).is_dir():
        raise EvsyncError(f'{option} {path}: a folder, not a file; nothing written')
    if not folder.is_dir():
        said = 'is a file, not a folder' if folder.exists() else 'does not exist'
        raise EvsyncError(f'{option} {path}: its folder {folder} {said}; nothing written')
