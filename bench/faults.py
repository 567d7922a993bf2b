"""Reliability table: every fault and bad input tried, how many times, survived or not, messages lost.

    ./dev run python bench/faults.py [--fuzz-examples 400] [--bag-trials 8] [--node-seeds 2] [--markdown]

Three parts, each the same code the test suite runs (``evsync_testing``: ``fuzz``, ``bagfaults``,
``nodefaults``), here with more trials and fresh random inputs:

* **bad input** (hypothesis): every fuzz property of the adapters and the estimators, with
  ``--fuzz-examples`` examples each, exploring afresh (not the suite's fixed examples). An example
  survives when it gives a result or a clear error (MessageError, StreamError, ParameterError) within
  the time limit; any other exception, or a hang, fails it.
* **bag faults**: truncated and corrupted storage (sqlite3 and mcap) at random points, a message
  whose topic or channel id names none (every reader passes over it), no metadata.yaml, an
  existing output, a write that fails at a random size, SIGKILL at a random moment, on a simulated
  12 s rig. Survived: the input untouched, and a clean refusal or a complete output (every message
  the input's index lists).
* **node faults**: a camera silent for 30 s, clock jumps back and forward on evt3 and dvs,
  duplicates, reordering, a 10x burst, restarts, each on a 50 s simulated rig per seed, through the
  node's real message path and DDS. Survived: every distinct message out exactly once, every camera
  locked again within 200 us of the truth, the fault reported in /diagnostics.

Messages lost: input messages missing from a finished output (bags) or from the node's outputs.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def fuzz_rows(examples: int) -> list[tuple[str, str, int, int, str]]:
    env = dict(os.environ, EVSYNC_FUZZ_EXAMPLES=str(examples), EVSYNC_FUZZ_RANDOM='1')
    done = subprocess.run([sys.executable, '-m', 'pytest', 'test/msg_adapters/test_fuzz_adapters.py',
                           'test/core/test_fuzz_estimators.py',
                           '-q', '-p', 'no:cacheprovider', '--hypothesis-show-statistics', '-rf'],
                          cwd=REPO, env=env, capture_output=True, text=True)
    out = done.stdout
    failed = set(re.findall(r'^FAILED (\S+)', out, re.M))
    rows = []
    for block in re.split(r'\n(?=test/\w+/test_fuzz_\w+\.py::)', out):
        head = re.match(r'(test/\w+/test_fuzz_(\w+)\.py::(\S+?)):?\n', block)
        if not head:
            continue
        counts = re.findall(r'(\d+) passing, (\d+) failing', block)
        passing = sum(int(p) for p, _ in counts)
        failing = sum(int(f) for _, f in counts)
        name = head.group(3).replace('test_', '', 1).replace('_', ' ')
        ok = head.group(1) not in failed and failing == 0
        rows.append(('bad input', f'{head.group(2)}: {name}', passing + failing, passing if ok else 0, '-'))
    if done.returncode not in (0, 1) or not rows:
        sys.exit(f'the fuzz run failed to run:\n{out[-3000:]}\n{done.stderr[-2000:]}')
    return rows


def bag_rows(trials: int, seed: int) -> list[tuple[str, str, int, int, str]]:
    from evsync_testing import bagfaults
    rng = np.random.default_rng(seed)
    root = Path(tempfile.mkdtemp(prefix='evsync-faults-'))
    bags, offsets = bagfaults.rigs(root, seed=3)
    t0 = time.perf_counter()
    subprocess.run([bagfaults.EVSYNC, 'restamp', str(bags['mcap']), str(root / 'timing'), '--offsets', str(offsets)],
                   capture_output=True, check=True)
    restamp_s = time.perf_counter() - t0
    results = defaultdict(list)
    k = 0

    def work() -> Path:
        nonlocal k
        k += 1
        path = root / f'w{k}'
        path.mkdir()
        return path

    for storage in ('sqlite3', 'mcap'):
        for _ in range(trials):
            for t in bagfaults.truncated(bags[storage], work(), fraction=float(rng.random()), offsets=offsets):
                results[t.fault].append(t)
            for t in bagfaults.corrupted(bags[storage], work(), seed=int(rng.integers(1 << 31)), offsets=offsets):
                results[t.fault].append(t)
            for t in bagfaults.passed_over(bags[storage], work(), seed=int(rng.integers(1 << 31)), offsets=offsets):
                results[t.fault].append(t)
            for t in bagfaults.write_failure(bags[storage], work(), fraction=float(rng.uniform(0.001, 1.0)),
                                             offsets=offsets):
                results[f'write fails at a random size ({storage})'].append(t)
        for t in bagfaults.missing_metadata(bags[storage], work(), offsets=offsets):
            results[f'no metadata.yaml ({storage})'].append(t)
    for _ in range(trials):
        for t in bagfaults.existing_output(bags['sqlite3'], work(), offsets=offsets):
            results[t.fault].append(t)
    for _ in range(2 * trials):
        for t in bagfaults.killed(bags['mcap'], work(), delay_s=float(rng.uniform(0.0, 1.3 * restamp_s)),
                                  offsets=offsets):
            results['SIGKILL at a random moment, then run again'].append(t)
    rows = []
    for fault, ts in results.items():
        outcomes = sorted({t.outcome for t in ts} | {t.fault.split('(')[-1].rstrip(')') for t in ts
                                                      if 'SIGKILL' in t.fault})
        rows.append(('bag', f'{fault} [{", ".join(outcomes)}]', len(ts), sum(t.survived for t in ts),
                     str(sum(t.lost for t in ts))))
        for t in ts:
            if not t.survived:
                print(f'bag fault not survived: {t.fault}: {t.detail}', file=sys.stderr)
    return rows


def node_rows(seeds: int) -> list[tuple[str, str, int, int, str]]:
    from evsync_testing import nodefaults
    results = defaultdict(list)
    for seed in range(seeds):
        bag = Path(tempfile.mkdtemp(prefix='evsync-node-faults-')) / 'rig'
        truth = nodefaults.sim_bag(bag, seconds=50, seed=11 + seed)
        msgs = nodefaults.read_messages(bag)
        verdicts = [nodefaults.silent_camera(truth, msgs, seconds=30.0)]
        verdicts += [nodefaults.jumping_clock(truth, msgs, encoding=e, by_s=b)
                     for e, b in (('dvs', -5.0), ('dvs', 7.0), ('evt3', 3.0), ('evt3', -4.0))]
        verdicts += [nodefaults.duplicated(truth, msgs, seed=seed), nodefaults.reordered(truth, msgs, seed=seed),
                     nodefaults.bursting(truth, msgs)]
        verdicts += [nodefaults.restarted(truth, msgs, at_s=a, before_lock=b)
                     for a, b in ((3.0, 'hold'), (20.0, 'hold'), (20.0, 'forward'))]
        for v in verdicts:
            results[v.fault].append(v)
            if not v.survived:
                print(f'node fault not survived (seed {seed}): {v.fault}: {"; ".join(v.problems)}', file=sys.stderr)
    return [('node', fault, len(vs), sum(v.survived for v in vs), str(sum(v.lost for v in vs)))
            for fault, vs in results.items()]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--fuzz-examples', type=int, default=400, help='examples per fuzz property')
    ap.add_argument('--bag-trials', type=int, default=8, help='random trials per bag fault and storage')
    ap.add_argument('--node-seeds', type=int, default=2, help='simulated rigs each node fault runs on')
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--markdown', action='store_true', help='a markdown table (for docs/reliability.md)')
    args = ap.parse_args()
    t0 = time.perf_counter()
    rows = fuzz_rows(args.fuzz_examples) + bag_rows(args.bag_trials, args.seed) + node_rows(args.node_seeds)
    elapsed = time.perf_counter() - t0
    head = ('part', 'fault or bad input', 'tried', 'survived', 'messages lost')
    if args.markdown:
        print('| ' + ' | '.join(head) + ' |')
        print('|' + '|'.join(['---', '---', '---:', '---:', '---:']) + '|')
        for r in rows:
            print(f'| {r[0]} | {r[1]} | {r[2]:,} | {r[3]:,} | {r[4]} |')
    else:
        width = max(len(r[1]) for r in rows)
        print(f'{head[0]:<10} {head[1]:<{width}} {head[2]:>7} {head[3]:>9} {head[4]:>14}')
        print('-' * (width + 46))
        for r in rows:
            print(f'{r[0]:<10} {r[1]:<{width}} {r[2]:>7,} {r[3]:>9,} {r[4]:>14}')
    tried, survived = sum(r[2] for r in rows), sum(r[3] for r in rows)
    lost = sum(int(r[4]) for r in rows if r[4] != '-')
    print(f'\n{tried:,} tried, {survived:,} survived, {lost} messages lost; {elapsed:.0f} s '
          f'(fuzz examples per property {args.fuzz_examples}, bag trials {args.bag_trials}, '
          f'node seeds {args.node_seeds})')
    sys.exit(0 if survived == tried and lost == 0 else 1)


if __name__ == '__main__':
    main()
