"""A session of bags in one command (``--jobs``) against the same bags one command at a time.

    ./dev run python bench/many_bags.py [--bags 4] [--jobs 2] [--duration 12] [--keep DIR]

``--bags`` simulated rigs (preset same-model, one seed each) are written as bags. Then, in one run,
each as its own process:

* ``evsync estimate BAG`` once per bag, one after another (the baseline: what a shell loop does);
* ``evsync estimate BAG... --jobs 1`` and ``--jobs J``;
* ``evsync restamp BAG OUT`` once per bag, one after another (the baseline);
* ``evsync restamp BAG... --output-dir DIR --jobs 1`` and ``--jobs J``.

Each many-bag run is checked against the baseline: every bag's estimate (``--json``) the same,
every restamped bag's messages (topics, record times, bytes, order) the same. The table gives wall
seconds and the ratio to the baseline; the host's cores and load average are printed beside it,
since ``--jobs`` can only gain where cores are free.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from evsync_ros.bag.reader import BagReader
from evsync_ros.sim import pixelsim, simbag

EVSYNC = str(Path(sys.executable).with_name('evsync'))


def digest(bag: Path) -> str:
    h = hashlib.sha256()
    with BagReader(bag) as reader:
        for conn, timestamp, raw in reader.messages(native=True):
            h.update(f'{conn.topic} {timestamp} {len(raw)}'.encode())
            h.update(raw)
    return h.hexdigest()


def timed(cmds: list[list[str]]) -> tuple[float, list[subprocess.CompletedProcess[str]]]:
    t0 = time.perf_counter()
    done = [subprocess.run(c, capture_output=True, text=True, check=False) for c in cmds]
    return time.perf_counter() - t0, done


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--bags', type=int, default=4)
    ap.add_argument('--jobs', type=int, default=2)
    ap.add_argument('--duration', type=float, default=12.0, help='seconds of each simulated rig (default 12)')
    ap.add_argument('--keep', metavar='DIR', help='work in DIR and keep it')
    args = ap.parse_args()
    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix='evsync-many-'))
    root.mkdir(parents=True, exist_ok=True)
    try:
        bags = []
        for seed in range(args.bags):
            rig = pixelsim.preset('same-model', seed=seed, duration_s=args.duration)
            bag = root / f'take{seed}'
            if not bag.exists():
                simbag.write_rig(rig, pixelsim.simulate(rig), bag)
            bags.append(bag)
        rows = estimate_rows(bags, args.jobs) + restamp_rows(bags, args.jobs, root)
    finally:
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)
    load = ', '.join(f'{x:.2f}' for x in os.getloadavg())
    print(f'{args.bags} bags of {args.duration:g} s; {os.cpu_count()} cores, load average {load} (at the end)')
    print(f'{"command":<44} {"seconds":>8} {"x baseline":>10}  same results')
    for name, seconds, base, same in rows:
        print(f'{name:<44} {seconds:>8.1f} {seconds / base:>10.2f}  {same}')
    return 0 if all(same in ('-', 'yes') for *_, same in rows) else 1


def estimate_rows(bags: list[Path], jobs: int) -> list[tuple[str, float, float, str]]:
    base, alone = timed([[EVSYNC, 'estimate', str(b), '--json'] for b in bags])
    expected = [json.loads(d.stdout) for d in alone]
    rows = [('evsync estimate BAG, one bag at a time', base, base, '-')]
    for j in sorted({1, jobs}):
        seconds, (done,) = timed([[EVSYNC, 'estimate', *map(str, bags), '--jobs', str(j), '--json']])
        got = [b['estimate'] for b in json.loads(done.stdout)['bags']]
        rows.append((f'evsync estimate BAG... --jobs {j}', seconds, base, 'yes' if got == expected else 'NO'))
    return rows


def restamp_rows(bags: list[Path], jobs: int, root: Path) -> list[tuple[str, float, float, str]]:
    single = root / 'single'
    shutil.rmtree(single, ignore_errors=True)
    single.mkdir()
    base, _ = timed([[EVSYNC, 'restamp', str(b), str(single / b.name)] for b in bags])
    expected = [digest(single / b.name) for b in bags]
    rows = [('evsync restamp BAG OUT, one bag at a time', base, base, '-')]
    for j in sorted({1, jobs}):
        out = root / f'jobs{j}'
        shutil.rmtree(out, ignore_errors=True)
        seconds, _ = timed([[EVSYNC, 'restamp', *map(str, bags), '--jobs', str(j), '--output-dir', str(out)]])
        same = [digest(out / b.name) for b in bags] == expected
        rows.append((f'evsync restamp BAG... --jobs {j} --output-dir', seconds, base, 'yes' if same else 'NO'))
    return rows


if __name__ == '__main__':
    sys.exit(main())
