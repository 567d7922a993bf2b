"""``die_with_parent``: a helper process ends with the process that started it, however that one
ends, and knows when its parent had gone before it asked."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

CHILD = ('import os, signal, sys, time\n'
         'from evsync_ros.lifetime import die_with_parent\n'
         'ok = die_with_parent(signal.SIGTERM, parent=int(sys.argv[1]))\n'
         'print(os.getpid(), ok, flush=True)\n'
         'time.sleep(60)\n')
PARENT = ('import subprocess, sys, os\n'
          'child = subprocess.Popen([sys.executable, "-c", sys.argv[1], str(os.getpid())], stdout=subprocess.PIPE,'
          ' text=True)\n'
          'print(child.stdout.readline().strip(), flush=True)\n'
          'child.wait()\n')


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie no reaper has taken yet has ended)."""
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except OSError:
        return False
    return state != 'Z'


@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='PR_SET_PDEATHSIG is Linux only')
def test_a_child_is_signalled_when_its_parent_is_killed():
    parent = subprocess.Popen([sys.executable, '-c', PARENT, CHILD], stdout=subprocess.PIPE, text=True)
    assert parent.stdout is not None
    pid, ok = parent.stdout.readline().split()
    assert ok == 'True'
    parent.send_signal(signal.SIGKILL)  # no cleanup of its own: only the kernel can tell the child
    parent.wait()
    deadline = time.monotonic() + 10
    while _alive(int(pid)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(int(pid)), 'the child outlived its parent'


def test_a_parent_that_is_not_this_process_s_parent_any_more_is_said():
    code = ('import os, signal\n'
            'from evsync_ros.lifetime import die_with_parent\n'
            'print(die_with_parent(signal.SIGTERM, parent=os.getppid()),'
            ' die_with_parent(signal.SIGTERM, parent=os.getppid() + 1_000_000), die_with_parent())\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ['True', 'False', 'True']
