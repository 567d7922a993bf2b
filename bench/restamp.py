"""Restamp throughput and memory on a simulated bag of 1 GB or more, against a plain copy of it.

    ./dev run python bench/restamp.py [--gb 1.0] [--storage sqlite3|mcap|ros1] [--rounds 3] [--keep DIR]
                                      [--profile]

A simulated rig (preset same-model, 33.55 s: 2^25 us, a whole number of evt3's 2^24 us cycles of
time words) is written as a bag, and that bag's messages are written again and again, each tile
one rig's length later on every clock (record times, header stamps and EventArray event times
moved; evt3 time words, whose sensor time then runs on unbroken, kept), until the bag reaches
``--gb``: a long recording for the purpose of moving bytes, written message by message, so that
the benchmark's own memory follows one tile at any size (``--gb 10``). Then, each in its own
process, in ``--rounds`` rounds (default 3), each round every run once in this order, each run's
output removed and the page cache's dirty pages written out (``sync``) before the next run starts,
so that no run pays for another's writes; a row's time is its median over the rounds:

* ``cp -r`` of the bag (the baseline: every byte read and written once, which cp does in the
  kernel, ``copy_file_range``);
* ``cat`` of the bag's storage file into a new file: every byte read into a process and written
  from it once, the least any program that changes bytes can cost (for reference);
* with ``--storage sqlite3``, sqlite itself inserting every message row into a new database
  (``INSERT ... SELECT``, unsynced, unjournalled, no Python per row): the floor of any writer that
  inserts rows, as rosbags' and evsync's do;
* with ``--storage sqlite3``, the bag's file copied and every row then changed in place (its record
  time moved and 8 bytes of its data replaced by a Python call per row, ``UPDATE``): the floor of a
  writer that would copy the file rather than insert rows (not evsync's; for reference);
* ``evsync restamp --offsets`` (the bag's true offsets: reading, restamping and writing only);
* ``evsync restamp`` (streamed estimate, then restamp: the bag read twice, or three times when a
  camera drifts);
* ``evsync estimate`` on the one-tile bag and on the tiled bag: peak resident memory against bag
  size (it should follow the estimation window, not the bag).

The commands run from Python's bytecode cache, as an installed package's do: ``RUN_ENV`` clears
PYTHONDONTWRITEBYTECODE, and ``warm`` fills the cache with one untimed run of each command first.

MB/s is input bag size over wall time; RSS is the peak resident set of the command's largest
process; CPU s the user and system time of all its processes (steadier than the wall on a shared
host); each ``x copy`` is the
row's median against the copy's, and ``range`` the least and greatest of that ratio within a
round (against that round's copy). With ``--storage
ros1`` the bags are ROS 1 ``.bag`` files, and one more row reads the tiled bag with rosbags' own
ROS 1 reader (which indexes every message before the first is read), against evsync_ros's, which
reads chunk by chunk.

``--profile``: then ``evsync restamp --offsets`` and ``evsync estimate`` on the tiled bag once more,
each in its own process with a timer around each stage (``bench/stages.py``: storage read, ROS 1
conversion, decode, binning, fitting, restamp, storage write, and the rest), beside the same
command's time without the timers from the table above.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.writer import BagWriter
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.sim import pixelsim, simbag
from msg_adapters.header import restamp_header
from msg_adapters.registry import is_event_type, restamp

RSS_PROBE = ('import resource, subprocess, sys; r = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL); '
             'u = resource.getrusage(resource.RUSAGE_CHILDREN); '
             'print(r.returncode, u.ru_maxrss, u.ru_utime + u.ru_stime)')


def size_of(path: Path) -> int:
    if path.is_file():
        return path.stat().st_size
    return sum(f.stat().st_size for f in path.rglob('*') if f.is_file())


ROSBAGS_READ = ('import sys; from rosbags.rosbag1 import Reader\n'
                'with Reader(sys.argv[1]) as r:\n    n = sum(1 for _ in r.messages())\nprint(n)')
OURS_READ = ('import sys; from evsync_ros.bag.reader import BagReader\n'
             'with BagReader(sys.argv[1]) as r:\n    n = sum(1 for _ in r.messages(native=True))\nprint(n)')

SQLITE_FLOOR = ('import sqlite3, sys; src, dst = sys.argv[1:]\n'
                'con = sqlite3.connect(dst, isolation_level=None); con.execute("ATTACH ? AS src", (src,))\n'
                'for (sql,) in con.execute("SELECT sql FROM src.sqlite_master WHERE type = \'table\' AND name NOT LIKE '
                '\'sqlite_%\'").fetchall(): con.execute(sql)\n'
                'con.execute("PRAGMA synchronous = OFF"); con.execute("PRAGMA journal_mode = OFF")\n'
                'con.execute("BEGIN"); con.execute("INSERT INTO main.messages SELECT * FROM src.messages")\n'
                'con.execute("COMMIT"); con.close()')
"""Every row of a sqlite3 bag's messages inserted into a new database by sqlite itself, unsynced and
unjournalled, with no Python per row: the least any writer that inserts rows can cost."""

SQLITE_IN_PLACE = ('import shutil, sqlite3, sys; src, dst = sys.argv[1:]\n'
                   'shutil.copyfile(src, dst); con = sqlite3.connect(dst, isolation_level=None)\n'
                   'con.execute("PRAGMA synchronous = OFF"); con.execute("PRAGMA journal_mode = OFF")\n'
                   'con.create_function("stamped", 1, lambda d: d[:4] + bytes(8) + d[12:], deterministic=True)\n'
                   'con.execute("BEGIN")\n'
                   'con.execute("UPDATE messages SET data = stamped(data), timestamp = timestamp + 1")\n'
                   'con.execute("COMMIT"); con.close()')
"""A sqlite3 bag's file copied, then every row changed in place (its record time moved, 8 bytes of
its data, where a header.stamp is, replaced by a Python call per row), unsynced and unjournalled (an
output renamed into place only once complete needs no journal): what a writer that copies the file
and changes each row in place, rather than inserting rows, would cost at least (docs/benchmarks.md)."""


RUN_ENV = {k: v for k, v in os.environ.items() if k != 'PYTHONDONTWRITEBYTECODE'}
"""The commands run as an installed package runs: from Python's bytecode cache, which pip and colcon
write when they install (a shell that sets PYTHONDONTWRITEBYTECODE would compile every module of
evsync_ros again on each command: about 0.08 s here). ``warm`` fills the cache first."""


def warm(evsync: str, bag: Path, offsets: Path, reference: str, work: Path) -> None:
    """One untimed ``restamp --offsets`` and ``estimate`` of the small bag: every module the timed
    commands import is then in Python's bytecode cache."""
    out = work / f'warm{bag.suffix}'
    for cmd in ((evsync, 'restamp', str(bag), str(out), '--offsets', str(offsets), '--reference', reference),
                (evsync, 'estimate', str(bag), '--reference', reference)):
        subprocess.run(cmd, stdout=subprocess.DEVNULL, check=True, env=RUN_ENV)
        remove(out)


def timed(*cmd: str) -> tuple[float, float, float]:
    """(seconds, peak RSS MB, CPU seconds: user and system, its children's with it) of a command in
    its own process, after the page cache's dirty pages are written out; fails loudly if it fails."""
    os.sync()
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, '-c', RSS_PROBE, *cmd], capture_output=True, text=True, check=True,
                         env=RUN_ENV)
    elapsed = time.perf_counter() - t0
    code, rss_kb, cpu = out.stdout.split()
    if code != '0':
        raise SystemExit(f'{" ".join(cmd)} exited {code}')
    return elapsed, int(rss_kb) / 1024, float(cpu)


STAGES_PY = Path(__file__).with_name('stages.py')


def staged(out: Path, *argv: str) -> tuple[float, dict[str, float]]:
    """(wall seconds, per-stage seconds) of ``evsync ARGV`` in its own process, timed by stage (run
    as ``timed`` runs the plain command, so that the two walls compare)."""
    wall, _, _ = timed(sys.executable, str(STAGES_PY), '--out', str(out), '--', *argv)
    stages = json.loads(out.read_text())
    stages['start-up and exit'] = wall - stages.pop('_main')
    return wall, stages


def print_profile(runs: dict[str, tuple[float, float, dict[str, float]]]) -> None:
    """Each run's stages (seconds and share of its wall time), its wall time with the timers, and
    without them (``runs``: {name: (plain seconds, timed wall seconds, stages)})."""
    names = list(runs)
    print(f'\n{"stage":<34}' + ''.join(f'{n:>26}' for n in names))
    print(f'{"":<34}' + ''.join(f'{"s":>18}{"%":>8}' for _ in names))
    print('-' * (34 + 26 * len(names)))
    for stage in next(iter(runs.values()))[2]:
        print(f'{stage:<34}' + ''.join(f'{st[stage]:>18.2f}{100 * st[stage] / wall:>8.1f}'
                                       for _, wall, st in runs.values()))
    print(f'{"wall, with the timers":<34}' + ''.join(f'{wall:>18.2f}{100.0:>8.1f}' for _, wall, _ in runs.values()))
    print(f'{"wall, without them (table above)":<34}' + ''.join(f'{plain:>18.2f}{"":>8}'
                                                                 for plain, _, _ in runs.values()))
    print('(the stages of a restamp are counted in one process; the table above\'s restamp reads and restamps in a '
          'second one while the first writes)')


def remove(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()


def print_rounds(results: dict[str, list[tuple[float, float, float]]], size: int, rounds: int) -> None:
    """Each run's median over the rounds: seconds, MB/s, against the copy (and the range of that
    ratio within a round), peak RSS, CPU seconds and against the copy's."""
    copy = results['cp -r']
    base = statistics.median(c[0] for c in copy)
    cpu_base = statistics.median(c[2] for c in copy)
    print(f'{rounds} rounds, each run once per round; medians, and the range of x copy within a round\n')
    print(f'{"run":<46} {"seconds":>8} {"MB/s":>8} {"x copy":>7} {"range":>12} {"peak RSS MB":>12} {"CPU s":>7} '
          f'{"x copy":>7}')
    print('-' * 114)
    for name, runs in results.items():
        secs = statistics.median(r[0] for r in runs)
        cpu = statistics.median(r[2] for r in runs)
        ratios = [r[0] / c[0] for r, c in zip(runs, copy)]
        spread = f'{min(ratios):.2f}-{max(ratios):.2f}'
        print(f'{name:<46} {secs:>8.2f} {size / 1e6 / secs:>8.0f} {secs / base:>7.2f} {spread:>12} '
              f'{max(r[1] for r in runs):>12.0f} {cpu:>7.2f} {cpu / cpu_base:>7.2f}')


TILE_NS = (1 << 25) * 1000
"""The rig's length: a whole number of evt3's 2^24 us cycles of time words."""


def write_tiled(one: Path, big: Path, *, tiles: int, span_ns: int, storage: str) -> None:
    """``tiles`` copies of the messages of the bag ``one``, one after another, copy j moved by j
    spans: record times, and every header.stamp and event time that the adapters' restamp moves
    (evt3 time words stay: ``span_ns`` is a whole number of their cycles)."""
    with BagReader(one) as reader:
        conns = {c.topic: c for c in reader.connections}
        messages = [(conn.topic, t, bytes(raw)) for conn, t, raw in reader.messages()]
    with BagWriter(big, storage=storage) as writer:
        out = {topic: writer.add_topic(topic, c.msgtype) for topic, c in conns.items()}
        for j in range(tiles):
            shift = ClockCorrection(offset_ns=j * span_ns)
            for topic, t, raw in messages:
                msgtype = conns[topic].msgtype
                data = restamp(raw, msgtype, shift) if is_event_type(msgtype) else restamp_header(raw, shift)
                writer.write(out[topic], t + j * span_ns, data)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--gb', type=float, default=1.0, help='least size of the tiled bag (default 1.0)')
    parser.add_argument('--storage', choices=('sqlite3', 'mcap', 'ros1'), default='sqlite3')
    parser.add_argument('--keep', metavar='DIR', help='work in DIR and keep the bags (default: a temporary directory)')
    parser.add_argument('--rounds', type=int, default=3, help='rounds of every run (default 3); medians are shown')
    parser.add_argument('--profile', action='store_true',
                        help='also time restamp --offsets and estimate per stage (bench/stages.py)')
    args = parser.parse_args()
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix='evsync-bench-restamp-'))
    work.mkdir(parents=True, exist_ok=True)
    evsync = str(Path(sys.executable).with_name('evsync'))
    try:
        rig = pixelsim.preset('same-model', seed=0, duration_s=TILE_NS / 1e9)
        events = pixelsim.simulate(rig)
        suffix = '.bag' if args.storage == 'ros1' else ''
        one = work / f'one{suffix}'
        simbag.write_rig(rig, events, one, storage=args.storage)
        k = math.ceil(args.gb * 1e9 / size_of(one))
        big = work / f'big{suffix}'
        t0 = time.perf_counter()
        write_tiled(one, big, tiles=k, span_ns=rig.scene.duration_ns, storage=args.storage)
        n_events = sum(e.t.size for e in events.values()) * k
        size = size_of(big)
        print(f'{args.storage} bag of {size / 1e9:.2f} GB: {k} tiles of {rig.scene.duration_ns / 1e9:.2f} s, '
              f'{len(rig.cameras)} cameras, {n_events:,} events (written in {time.perf_counter() - t0:.0f} s)\n')
        truth = json.loads((work / f'one{suffix}.truth.json').read_text())
        offsets = work / 'offsets.json'
        offsets.write_text(json.dumps(truth))
        restamp_args = ('--offsets', str(offsets), '--reference', rig.reference)
        runs = {'cp -r': ('cp', '-r', str(big), str(work / 'copy')),
                'cat, into a new file': ('sh', '-c', 'cat "$@" > "$0"', str(work / 'cat'),
                                         *(map(str, sorted(big.iterdir())) if big.is_dir() else [str(big)]))}
        if args.storage == 'sqlite3':
            (db,) = big.glob('*.db3')
            runs['sqlite3 INSERT ... SELECT, every row (floor)'] = (sys.executable, '-c', SQLITE_FLOOR, str(db),
                                                                     str(work / 'floor.db3'))
            runs['sqlite3 file copied, every row changed in place'] = (sys.executable, '-c', SQLITE_IN_PLACE,
                                                                       str(db), str(work / 'inplace.db3'))
        if args.storage == 'ros1':
            runs['rosbags ROS 1 reader, every message'] = (sys.executable, '-c', ROSBAGS_READ, str(big))
            runs['evsync_ros ROS 1 reader, every message'] = (sys.executable, '-c', OURS_READ, str(big))
        runs['evsync restamp --offsets (restamp only)'] = (evsync, 'restamp', str(big), str(work / f'out{suffix}'),
                                                           *restamp_args)
        runs['evsync restamp (estimate, then restamp)'] = (evsync, 'restamp', str(big), str(work / f'out{suffix}'),
                                                           '--reference', rig.reference)
        warm(evsync, one, offsets, rig.reference, work)
        results: dict[str, list[tuple[float, float, float]]] = {name: [] for name in runs}
        for _ in range(args.rounds):
            for name, cmd in runs.items():
                results[name].append(timed(*cmd))
                out = work / f'out{suffix}'
                if out.exists() and size_of(out) < 0.9 * size:
                    raise SystemExit('the restamped bag is smaller than the input: something was lost')
                for left in ('copy', 'cat', 'floor.db3', 'inplace.db3', f'out{suffix}'):
                    remove(work / left)
        print_rounds(results, size, args.rounds)
        est_one = timed(evsync, 'estimate', str(one), '--reference', rig.reference)
        est_big = timed(evsync, 'estimate', str(big), '--reference', rig.reference)
        print(f'\nevsync estimate, peak RSS: {size_of(one) / 1e6:.0f} MB bag {est_one[1]:.0f} MB; '
              f'{size / 1e6:.0f} MB bag {est_big[1]:.0f} MB ({size / size_of(one):.0f}x the bag, '
              f'{est_big[1] / est_one[1]:.2f}x the memory), in {est_big[0]:.1f} s')
        if args.profile:
            plain = statistics.median(r[0] for r in results['evsync restamp --offsets (restamp only)'])
            stages = {'restamp --offsets': (plain, *staged(work / 'stages1.json', 'restamp', str(big),
                                                             str(work / f'out3{suffix}'), *restamp_args)),
                    'estimate': (est_big[0], *staged(work / 'stages2.json', 'estimate', str(big),
                                                     '--reference', rig.reference))}
            print_profile(stages)
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == '__main__':
    main()
