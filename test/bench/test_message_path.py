"""bench/message_path.py --stages: each stage of a locked message is timed (the C call caught where the
decoder looks it up, the feed and the publish where the path calls them), the timers' own cost measured
and taken out, and together they make up no more than the whole message."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parents[2]
MESSAGE_PATH_PY = ROOT / 'bench' / 'message_path.py'


def test_stages_account_for_a_locked_message():
    path = os.pathsep.join(  # bench/node.py imports the test support, as ./dev run puts it on the path
        filter(None, [str(ROOT / 'test' / 'support'), str(ROOT), os.environ.get('PYTHONPATH')]))
    argv = [sys.executable, str(MESSAGE_PATH_PY), '--cameras', '2', '--rate', '1', '--seconds', '6', '--stages']
    run = subprocess.run(argv, capture_output=True, text=True, timeout=300, env={**os.environ, 'PYTHONPATH': path})
    assert run.returncode == 0, run.stderr
    head = re.search(r"where a locked message's time goes \((\d+) messages, wall us each, ([\d.]+) in all; "
                     r'each of its 4 inner timers, ([\d.]+) us, taken out\)', run.stdout)
    assert head, run.stdout
    messages, whole, timer = int(head.group(1)), float(head.group(2)), float(head.group(3))
    stages = {what: float(us) for us, what in re.findall(r'^\s+(-?[\d.]+)  (.+)$', run.stdout[head.end():], re.M)}
    assert messages > 1000 and whole > 0 and 0 < timer < 5, run.stdout
    assert set(stages) == {'the C call (decode, count, retime, output)', "its decoder's Python around it",
                           "the estimate's feed", 'the publish', 'the rest of the path'}, stages
    assert all(v > 0 for v in stages.values()), stages  # the rest too: the timed stages lie within the whole
