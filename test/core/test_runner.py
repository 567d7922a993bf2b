import os
import signal
import subprocess
import sys

import pytest

from evsync_ros.core.runner import InThread
from evsync_ros.errors import ParameterError, StreamError
from evsync_ros.runtime.runner import InProcess, runner


def square_and_pid(x):
    return x * x, os.getpid()


def refuse(x):
    raise ValueError(f'no {x}')


def die():
    os.kill(os.getpid(), signal.SIGKILL)


def niceness():
    return os.getpriority(os.PRIO_PROCESS, 0)


@pytest.fixture
def worker():
    r = InProcess()
    yield r
    r.close()


def test_in_process_runs_each_call_in_its_worker_in_order(worker):
    out = worker.run(square_and_pid, [(k,) for k in range(20)])
    assert [v for v, _ in out] == [k * k for k in range(20)]
    assert {pid for _, pid in out} == {worker.pid} and worker.pid != os.getpid()
    assert worker.run(square_and_pid, []) == []


def test_in_thread_runs_each_call_here():
    assert InThread().run(square_and_pid, [(3,)]) == [(9, os.getpid())]


def test_what_a_call_raises_is_raised_by_run(worker):
    with pytest.raises(ValueError, match='no 7'):
        worker.run(refuse, [(7,)])
    assert worker.run(square_and_pid, [(2,)])[0][0] == 4  # and the worker goes on


def test_a_worker_that_dies_is_started_again(worker):
    dead = worker.pid
    os.kill(dead, signal.SIGKILL)
    out = worker.run(square_and_pid, [(5,)])
    assert out[0][0] == 25 and out[0][1] == worker.pid != dead
    assert worker.restarts == 1


def test_the_worker_takes_the_niceness_asked_for():
    r = InProcess(nice=7)
    try:
        assert r.run(niceness, [()]) == [min(niceness() + 7, 19)]
    finally:
        r.close()


def test_closed_worker_is_gone():
    r = InProcess()
    pid = r.pid
    r.close()
    with pytest.raises(ProcessLookupError):  # reaped: not even a zombie of it is left
        os.kill(pid, 0)


def test_runner_names():
    assert isinstance(runner('thread'), InThread)
    with pytest.raises(ParameterError, match='estimator must be one of'):
        runner('threads')


def test_a_worker_that_keeps_dying_is_an_error():
    r = InProcess()
    try:
        with pytest.raises(StreamError, match='died twice'):
            r.run(die, [()])  # the worker started again dies as well
        assert r.restarts == 1
    finally:
        r.close()


def test_a_script_without_a_main_guard_can_start_a_worker(tmp_path):
    # multiprocessing's spawn ran the parent's main script again in the worker, and such a script
    # started workers without end (a user's script building the node at its top level)
    script = tmp_path / 'unguarded.py'
    script.write_text('from evsync_ros.runtime.runner import InProcess\n'
                      'import math\n'
                      'r = InProcess()\n'
                      'print(r.run(math.factorial, [(5,), (6,)]))\n'
                      'r.close()\n')
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == '[120, 720]'
