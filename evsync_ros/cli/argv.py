"""Command lines as users type them: options before or after the positionals.

argparse gives an option of one or more values (``--topics /a /b``) every word up to the next option,
so ``evsync estimate --topics /a /b BAG`` hands it the bag too, and then misses the bag.
``positionals_last`` gives back, from the end of such runs, the positionals the command is short
of, and puts the positionals first, where argparse takes them before any option. A command of
several bags (a positional of one or more) takes back, besides, every word that ends a run and
names a path that exists (``evsync estimate --topics /a /b BAG1 BAG2``): a topic is no file.
What each option takes is the command's own declaration (``Spec``, kept by ``command.Arguments``).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ['OPTIONAL_NUMBER', 'Spec', 'positionals_last']

OPTIONAL_NUMBER = -1
"""What an option of an optional value takes: a word when it is a number (evsync's are rates)."""


@dataclass(frozen=True)
class Spec:
    """A command line's shape: each positional's ``nargs`` (None: one), the option strings of options
    of one or more words, and how many words each other option takes (``OPTIONAL_NUMBER``: one when
    it is a number; an option not named here takes none, as ``--help``)."""

    positionals: tuple[int | str | None, ...] = ()
    many: frozenset[str] = frozenset()
    takes: Mapping[str, int] = field(default_factory=dict)


class Kind(enum.Enum):
    """What a word of a command line is."""

    OPTION = 'option'
    VALUE = 'value'
    """An option's value (one of the fixed number it takes)."""
    RUN = 'run'
    """One of the words of a many-valued option (``--topics /a /b``)."""
    POSITIONAL = 'positional'


Words = list[tuple[Kind, str]]
"""A command line's words, each with its kind."""


def positionals_last(spec: Spec, argv: Sequence[str], *, least: int | None = None) -> list[str]:
    """``argv`` of a command line of shape ``spec`` with its positionals first: as given when there are
    enough of them, else with the missing ones taken from the ends of its many-valued options' runs
    (the last run first, each run keeping a value of its own). ``least``: the fewest positionals the command line
    needs (default: one per positional, one for a positional of one or more). When the command has a
    positional of one or more, the paths that exist at the ends of the runs are positionals too."""
    needed = sum(1 for nargs in spec.positionals if nargs in (None, 1, '+')) if least is None else least
    args = list(argv)
    words, runs = _words(spec, args)
    missing = needed - sum(kind is Kind.POSITIONAL for kind, _ in words)
    moved = missing > 0  # as before there were commands of several bags: reordered whenever short
    for run in reversed(runs):
        while missing > 0 and len(run) > 1:
            _take(words, run)
            missing -= 1
    if '+' in spec.positionals:
        for run in reversed(runs):
            while len(run) > 1 and Path(words[run[-1]][1]).exists():
                _take(words, run)
                moved = True
    if not moved:
        return args
    positionals = [t for kind, t in words if kind is Kind.POSITIONAL]
    return positionals + [t for kind, t in words if kind is not Kind.POSITIONAL]


def _take(words: Words, run: list[int]) -> None:
    """The last word of a many-valued option's run, a positional."""
    k = run.pop()
    words[k] = (Kind.POSITIONAL, words[k][1])


def _words(spec: Spec, args: list[str]) -> tuple[Words, list[list[int]]]:
    """``args`` as words, and each many-valued option's run (the indices of its words)."""
    plus, takes = spec.many, spec.takes
    words: Words = []
    runs: list[list[int]] = []
    i = 0
    while i < len(args):
        token = args[i]
        if token == '--':
            words += [(Kind.POSITIONAL, t) for t in args[i + 1:]]
            break
        name = token.split('=', 1)[0]
        if not (token.startswith('-') and len(token) > 1 and not _number(token)):
            words.append((Kind.POSITIONAL, token))
            i += 1
            continue
        words.append((Kind.OPTION, token))
        i += 1
        if '=' in token:
            continue
        if name in plus:
            runs.append([])
            while i < len(args) and not (args[i].startswith('-') and not _number(args[i])):
                runs[-1].append(len(words))
                words.append((Kind.RUN, args[i]))
                i += 1
        elif takes.get(name) == OPTIONAL_NUMBER:
            if i < len(args) and _number(args[i]):
                words.append((Kind.VALUE, args[i]))
                i += 1
        else:
            for _ in range(takes.get(name, 0)):
                if i < len(args):
                    words.append((Kind.VALUE, args[i]))
                    i += 1
    return words, runs


def _number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True
