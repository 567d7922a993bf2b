"""Faults of the bag tools, each run once and judged: the tests and ``bench/faults.py`` run them.

A trial damages a copy of a recording (or its output's surroundings), runs ``evsync`` on it, and
judges the outcome by what the conventions promise:

* the input is untouched (every file's SHA-256 before and after);
* the command either refuses with exit status 2 and an error naming the bag or the output, leaving
  no output, or finishes (0, or 1 with its bad messages counted) with an output that is complete:
  readable, every input message in it;
* nothing that looks like an output is left beside it (hidden ``.partial`` directories of a killed
  run excepted: those are never at the output path, and the next run removes them).
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import os
import resource
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from evsync_ros.bag.reader import BagReader
from evsync_ros.cli import main as cli
from evsync_testing.crafted import edit_mcap_channel

EVSYNC = str(Path(sys.executable).parent / 'evsync')


@dataclass
class Trial:
    fault: str
    outcome: str
    """'refused', 'done', 'done, bad messages counted', or what went wrong."""
    survived: bool
    lost: int = 0
    """Input messages missing from a finished output."""
    detail: str = ''


def digest(path: Path) -> dict[str, str]:
    files = [path] if path.is_file() else sorted(p for p in path.rglob('*') if p.is_file())
    return {str(f.relative_to(path.parent)): hashlib.sha256(f.read_bytes()).hexdigest() for f in files}


def partials(parent: Path) -> list[Path]:
    return sorted(parent.glob('.*.partial'))


def message_count(bag: Path) -> int:
    with BagReader(bag) as reader:
        return sum(1 for _ in reader.messages())


def listed_count(bag: Path) -> int:
    """The messages the bag's storage files' own indexes list (``BagReader.listed``): what a finished
    output must hold, those the readers pass over included."""
    with BagReader(bag) as reader:
        return sum(reader.listed().values())


def run_cli(*argv: str) -> tuple[int, str]:
    """``evsync ARGV`` in this process: (exit status, what it wrote to stderr)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = cli.main(list(argv))
    return code, err.getvalue()


def storage_file(bag: Path) -> Path:
    return next(p for p in sorted(bag.iterdir()) if p.suffix in ('.db3', '.mcap'))


def judge(fault: str, code: int, err: str, *, src: Path, before: dict, out: Path | None, expected: int | None,
          names: tuple[str, ...]) -> Trial:
    """A trial's verdict (module notes); ``expected``: messages a finished output must hold."""
    problems = []
    if digest(src) != before:
        problems.append('input changed')
    lost = 0
    if code == 2:
        outcome = 'refused'
        if not any(n in err for n in names):
            problems.append(f'error names none of {names}: {err.strip()[-200:]}')
        if out is not None and out.exists():
            problems.append('refused but an output exists')
    elif code in (0, 1):
        outcome = 'done' if code == 0 else 'done, bad messages counted'
        if out is not None:
            try:
                got = message_count(out)
            except Exception as exc:  # noqa: BLE001 (an unreadable output is this trial's failure)
                problems.append(f'output unreadable: {exc}')
                got = 0
            if expected is not None:
                lost = max(0, expected - got)
                if got != expected:
                    problems.append(f'output holds {got} of {expected} messages')
    else:
        outcome = f'exit {code}'
        problems.append(f'exit status {code}: {err.strip()[-300:]}')
    parent = (out or src).parent
    if out is not None and [p for p in partials(parent) if p.name.startswith(f'.{out.name}.')]:
        problems.append('a partial output left behind')
    return Trial(fault, outcome, not problems, lost, '; '.join(problems))


def rigs(root: Path, *, seed: int) -> tuple[dict[str, Path], Path]:
    """A 12 s simulated rig in both storages, and its offsets as ``evsync estimate --json`` writes them."""
    bags = {}
    for storage in ('sqlite3', 'mcap'):
        with contextlib.redirect_stdout(io.StringIO()):
            assert cli.main(['simulate', str(root / storage), '--preset', 'same-model', '--duration', '12',
                             '--seed', str(seed), '--storage', storage]) == 0
        bags[storage] = root / storage
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
        assert cli.main(['estimate', str(bags['sqlite3']), '--json']) == 0
    offsets = root / 'offsets.json'
    offsets.write_text(buf.getvalue())
    return bags, offsets


# -- the faults -------------------------------------------------------------------------------------

def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def truncated(src: Path, work: Path, *, fraction: float, offsets: Path) -> list[Trial]:
    """The storage file cut at ``fraction`` of its size (a recorder killed, a copy interrupted)."""
    bag = _copy(src, work / 'in')
    f = storage_file(bag)
    os.truncate(f, int(f.stat().st_size * fraction))
    return _read_and_restamp(f'truncated storage ({f.suffix[1:]})', bag, work, offsets)


def corrupted(src: Path, work: Path, *, seed: int, offsets: Path) -> list[Trial]:
    """Random spans of the storage file overwritten with random bytes (a bad disk, a bad copy)."""
    bag = _copy(src, work / 'in')
    f = storage_file(bag)
    rng = np.random.default_rng(seed)
    data = bytearray(f.read_bytes())
    for at in rng.integers(0, len(data) - 64, int(rng.integers(1, 9))):
        data[at:at + 16] = rng.bytes(16)
    f.write_bytes(bytes(data))
    return _read_and_restamp(f'corrupted storage ({f.suffix[1:]})', bag, work, offsets)


def passed_over(src: Path, work: Path, *, seed: int, offsets: Path) -> list[Trial]:
    """One message of a random camera whose topic id (sqlite3) or channel id (mcap) names none: every
    reader passes over it, rosbags' too, and a whole read must not finish without it."""
    bag = _copy(src, work / 'in')
    f = storage_file(bag)
    rng = np.random.default_rng(seed)
    if f.suffix == '.mcap':
        edit_mcap_channel(f, f, channel=999, which=int(rng.integers(1, 20)))
    else:
        with sqlite3.connect(f) as db:
            (rows,) = db.execute('SELECT count(*) FROM messages').fetchone()
            db.execute('UPDATE messages SET topic_id=999 WHERE id=?', (int(rng.integers(1, rows + 1)),))
        db.close()
    return _read_and_restamp(f'a message of no topic or channel ({f.suffix[1:]})', bag, work, offsets)


def _read_and_restamp(fault: str, bag: Path, work: Path, offsets: Path) -> list[Trial]:
    before = digest(bag)
    names = (str(bag),)
    code, err = run_cli('estimate', str(bag), '--json')
    trials = [judge(f'{fault}: estimate', code, err, src=bag, before=before, out=None, expected=None, names=names)]
    out = work / 'out'
    code, err = run_cli('restamp', str(bag), str(out), '--offsets', str(offsets))
    expected = None
    if code in (0, 1):
        try:  # what the input's index lists is what a finished output must hold
            expected = listed_count(bag)
        except Exception:  # noqa: BLE001
            expected = None
    trials.append(judge(f'{fault}: restamp', code, err, src=bag, before=before, out=out, expected=expected,
                        names=names))
    return trials


def missing_metadata(src: Path, work: Path, *, offsets: Path) -> list[Trial]:
    """No metadata.yaml (a recorder killed before writing it): read from the storage files."""
    bag = _copy(src, work / 'in')
    (bag / 'metadata.yaml').unlink()
    before = digest(bag)
    out = work / 'out'
    code, err = run_cli('restamp', str(bag), str(out), '--offsets', str(offsets))
    trial = judge('missing metadata.yaml: restamp', code, err, src=bag, before=before, out=out,
                  expected=message_count(src), names=(str(bag),))
    if trial.survived and code != 0:
        trial.survived, trial.detail = False, f'refused a bag its storage files hold: {err.strip()[-200:]}'
    return [trial]


def existing_output(src: Path, work: Path, *, offsets: Path) -> list[Trial]:
    """The output path exists already (a bag from before, a typo): refused, left as it was."""
    out = work / 'out'
    out.mkdir()
    (out / 'keep.txt').write_text('mine')
    before_out, before = digest(out), digest(src)
    code, err = run_cli('restamp', str(src), str(out), '--offsets', str(offsets))
    trial = judge('output exists', code, err, src=src, before=before, out=None, expected=None, names=(str(out),))
    if code != 2 or digest(out) != before_out:
        trial.survived, trial.detail = False, f'exit {code}; existing output changed: {digest(out) != before_out}'
    return [trial]


def write_failure(src: Path, work: Path, *, fraction: float, offsets: Path) -> list[Trial]:
    """The output cannot be written past ``fraction`` of its size (RLIMIT_FSIZE: a full disk, a quota)."""
    limit = int(sum(p.stat().st_size for p in src.iterdir()) * fraction)

    def limited() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead of killing
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    before = digest(src)
    out = work / 'out'
    done = subprocess.run([EVSYNC, 'restamp', str(src), str(out), '--offsets', str(offsets)],
                          capture_output=True, text=True, preexec_fn=limited, timeout=120, check=False)
    trial = judge(f'write fails ({fraction:.0%} of the output)', done.returncode, done.stderr, src=src,
                  before=before, out=out, expected=message_count(src), names=(str(out),))
    return [trial]


def killed(src: Path, work: Path, *, delay_s: float, offsets: Path) -> list[Trial]:
    """``evsync restamp`` killed with SIGKILL after ``delay_s``; then run again to the same output."""
    before = digest(src)
    out = work / 'out'
    proc = subprocess.Popen([EVSYNC, 'restamp', str(src), str(out), '--offsets', str(offsets)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    time.sleep(delay_s)
    proc.kill()
    proc.wait()
    phase = ('finished first' if proc.returncode == 0 else 'after the rename' if out.exists()
             else 'while writing' if partials(work) else 'before writing')
    problems = []
    if digest(src) != before:
        problems.append('input changed')
    if out.exists():  # the rename is the last step: whatever is at the output path must be whole
        if message_count(out) != message_count(src):
            problems.append('a killed run left an incomplete output at the output path')
        shutil.rmtree(out)
    stale = partials(work)
    code, err = run_cli('restamp', str(src), str(out), '--offsets', str(offsets))
    again = judge('', code, err, src=src, before=before, out=out, expected=message_count(src), names=(str(out),))
    if not again.survived or code != 0:
        problems.append(f'the run after: exit {code} {again.detail}')
    if stale and partials(work):
        problems.append(f'the run after left {partials(work)}')
    return [Trial(f'SIGKILL during restamp ({phase})', 'killed; the next run complete', not problems, again.lost,
                  '; '.join(problems))]
