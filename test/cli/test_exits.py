"""Issue 52: how every evsync command ends. A closed pipe (``| head``) ends it silently with 141 (the
shell's status of a command SIGPIPE ends); ``--version``; help in plain text; every command and
option a row of the table of commands, none of argparse's private parts used (issue 51)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import evsync_ros
from evsync_ros.cli.command import Exit
from evsync_ros.cli.main import COMMANDS, build_parser, main

EVSYNC = str(Path(sys.executable).with_name('evsync'))
CLI = Path(evsync_ros.__file__).parent / 'cli'


@pytest.fixture(scope='module')
def rig(tmp_path_factory) -> Path:
    bag = tmp_path_factory.mktemp('rig') / 'rig'
    assert main(['simulate', str(bag), '--preset', 'same-model', '--duration', '12']) == 0
    return bag


def closed_pipe(*argv: str) -> tuple[int, str]:
    """Run ``evsync ARGV`` with its standard output a pipe whose reader has gone before it writes:
    (exit status, standard error)."""
    proc = subprocess.Popen([EVSYNC, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    proc.stdout.close()
    _, err = proc.communicate(timeout=300)
    return proc.returncode, err


@pytest.mark.parametrize('argv', [['estimate', '{bag}', '--json'], ['report', '{bag}'], ['estimate', '{bag}'],
                                  ['plotjuggler']])
def test_a_closed_pipe_ends_a_command_silently_with_141(rig, argv):
    code, err = closed_pipe(*(a.format(bag=rig) for a in argv))
    assert code == 141 == int(Exit.CLOSED_PIPE), err
    assert err == '', err  # no BrokenPipeError, no "internal error", no traceback


@pytest.mark.parametrize('jobs', ['1', '2'])
def test_a_closed_pipe_ends_a_command_of_several_bags_with_141(rig, jobs):
    code, err = closed_pipe('estimate', str(rig), str(rig), '--jobs', jobs)
    assert code == 141, err
    assert 'Traceback' not in err and 'internal error' not in err and 'died' not in err, err


def test_head_reads_what_it_wants_and_the_command_ends_quietly(rig):
    """As typed: the shell's pipeline, with the command's status."""
    for command in (f'{EVSYNC} estimate {rig} --json | head -c 20', f'{EVSYNC} report {rig} | head -2'):
        done = subprocess.run(['bash', '-c', f'{command}; echo "status ${{PIPESTATUS[0]}}" >&2'],
                              capture_output=True, text=True, timeout=300)
        status = int(done.stderr.strip().splitlines()[-1].split()[-1])
        assert status in (0, 141), done.stderr  # 0: it had written all before head went
        assert done.stderr.strip().splitlines() == [f'status {status}'], done.stderr
    assert len(done.stdout.splitlines()) == 2


def test_version_says_the_package_version():
    done = subprocess.run([EVSYNC, '--version'], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout == f'evsync {evsync_ros.__version__}\n'


def test_help_is_plain_text():
    """No reStructuredText (``literal``) or Markdown (`code`) marks in any help a user reads."""
    helps = {'evsync': build_parser().format_help()}
    helps.update({name: c.parser()[0].format_help() for name, c in COMMANDS.items()})
    for name, text in helps.items():
        assert '`' not in text, (name, text)
        assert '``' not in text
    assert 'The evsync command line' in helps['evsync'] and '--version' in helps['evsync']
    assert list(COMMANDS) == ['demo', 'simulate', 'estimate', 'restamp', 'report', 'verify', 'plotjuggler', 'play']


def test_every_command_s_help_runs():
    for name in COMMANDS:
        done = subprocess.run([EVSYNC, name, '--help'], capture_output=True, text=True, timeout=60)
        assert done.returncode == 0 and done.stdout.startswith(f'usage: evsync {name}'), (name, done.stderr)


def test_an_unknown_command_is_a_usage_error():
    done = subprocess.run([EVSYNC, 'estimat'], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "invalid choice: 'estimat'" in done.stderr


def _sizes(path: Path) -> list[tuple[str, int, int]]:
    """(name, kind: 0 function 1 class, lines) of every function and class defined in ``path``."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            kind = 1 if isinstance(node, ast.ClassDef) else 0
            out.append((f'{path.name}:{node.name}', kind, (node.end_lineno or node.lineno) - node.lineno + 1))
    return out


def test_the_command_line_is_in_small_parts():
    """Issue 51: no function of 100 lines or more, no class of 300, main.py a table and its door."""
    sizes = [s for path in sorted(CLI.glob('*.py')) for s in _sizes(path)]
    assert len(sizes) > 50  # the walk sees the modules
    too_long = [(name, n) for name, kind, n in sizes if n >= (300 if kind else 100)]
    assert not too_long, too_long
    assert len((CLI / 'main.py').read_text().splitlines()) < 150


def test_no_private_part_of_argparse_is_used():
    """The command line shapes what it declares (command.Arguments), not argparse's ``_actions``."""
    for path in CLI.glob('*.py'):
        tree = ast.parse(path.read_text())
        private = [n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute) and n.attr.startswith('_')
                   and not n.attr.startswith('__') and isinstance(n.value, ast.Name)
                   and n.value.id in ('argparse', 'parser', 'ap', 'sub', 'action')]
        assert not private, (path.name, private)
        assert '_actions' not in path.read_text(), path.name
