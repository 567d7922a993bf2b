"""Issue 40, "Many bags": ``evsync estimate`` and ``restamp`` over several bags in one command, each
bag in a process of its own (``--jobs``), each getting the result it gets alone; a bad bag its own
error, the others done; the summary and the exit status of them all."""

from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.writer import BagWriter
from evsync_ros.cli import batch
from evsync_ros.cli.main import main, parse

EVSYNC = str(Path(sys.executable).with_name('evsync'))


@pytest.fixture(scope='module')
def bags(tmp_path_factory) -> list[Path]:
    """Three takes: two simulated rigs of different seeds (so that a bag given the other's result
    shows), and a copy of the first."""
    root = tmp_path_factory.mktemp('session')
    out = []
    for seed in (1, 2):
        bag = root / f'take{seed}'
        assert main(['simulate', str(bag), '--preset', 'same-model', '--duration', '12', '--seed', str(seed)]) == 0
        out.append(bag)
    shutil.copytree(out[0], root / 'take3')
    return [*out, root / 'take3']


def summary(out: str) -> dict[str, list[str]]:
    """The summary table's rows, by bag: result, exit, accepted, seconds (and output)."""
    lines = out.rsplit(' at a time\n', maxsplit=1)[-1].split('\n\n', maxsplit=1)[0].splitlines()
    assert lines[0].split()[:3] == ['bag', 'result', 'exit'] and set(lines[1]) == {'-'}
    return {line.split()[0]: line.split()[1:] for line in lines[2:]}


def digest(bag: Path) -> str:
    """sha256 of a bag's topics and of its messages in read order (record times and bytes)."""
    h = hashlib.sha256()
    with BagReader(bag) as reader:
        for conn in sorted(reader.connections, key=lambda c: c.topic):
            h.update(repr((conn.topic, conn.msgtype, conn.msgdef.data, conn.digest)).encode())
        for conn, timestamp, raw in reader.messages(native=True):
            h.update(f'{conn.topic} {timestamp} {len(raw)}'.encode())
            h.update(raw)
    return h.hexdigest()


def alone(capsys, *argv: str) -> tuple[int, dict]:
    capsys.readouterr()
    code = main(['estimate', *argv, '--json'])
    return code, json.loads(capsys.readouterr().out)


def test_estimate_jobs_gives_each_bag_the_result_it_gets_alone(bags, capsys):
    expected = [alone(capsys, str(b)) for b in bags]
    assert expected[0] != expected[1] and expected[0] == expected[2]  # two rigs, and a copy
    capsys.readouterr()
    code = main(['estimate', *map(str, bags), '--jobs', '2', '--json'])
    out = capsys.readouterr().out
    assert out.count('\n') == 1  # one JSON object
    doc = json.loads(out)
    assert code == 0
    assert [b['bag'] for b in doc['bags']] == [str(b) for b in bags]
    for entry, (status, estimate) in zip(doc['bags'], expected):
        assert entry['exit'] == status == 0 and entry['result'] == 'done' and entry['error'] is None
        assert entry['estimate'] == estimate
        assert entry['cameras'] == len(estimate['cameras']) == entry['cameras_accepted']


def test_restamp_jobs_writes_each_bag_as_it_is_written_alone(bags, tmp_path, capsys):
    single = tmp_path / 'single'
    single.mkdir()
    for bag in bags:
        assert main(['restamp', str(bag), str(single / bag.name)]) == 0
    capsys.readouterr()
    code = main(['restamp', *map(str, bags), '--jobs', '2', '--output-dir', str(tmp_path / 'many')])
    rows = summary(capsys.readouterr().out)
    assert code == 0
    for bag in bags:
        out = tmp_path / 'many' / bag.name
        assert digest(out) == digest(single / bag.name)
        with BagReader(out) as many, BagReader(single / bag.name) as one:
            assert many.provenance is not None and one.provenance is not None
            assert many.provenance['estimate'] == one.provenance['estimate']
        assert rows[str(bag)][:3] == ['done', '0', '3/3'] and rows[str(bag)][-1] == str(out)
    assert sorted(p.name for p in (tmp_path / 'many').iterdir()) == [b.name for b in bags]  # nothing else


def test_one_bad_bag_gets_its_own_error_and_the_others_are_done(bags, tmp_path, capsys):
    bad = tmp_path / 'notabag'
    bad.mkdir()
    (bad / 'metadata.yaml').write_text('this is not a rosbag2\n')
    order = [bags[0], bad, bags[1]]
    capsys.readouterr()
    code = main(['estimate', *map(str, order), '--jobs', '2', '--json'])
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    assert code == 2
    good, wrong, other = doc['bags']
    assert good['result'] == other['result'] == 'done' and good['estimate'] and other['estimate']
    assert wrong['result'] == 'error' and wrong['exit'] == 2 and wrong['estimate'] is None
    assert str(bad) in wrong['error']
    assert f'{bad}: evsync: error: {wrong["error"]}' in captured.err  # its lines named by the bag

    outdir = tmp_path / 'out'
    code = main(['restamp', *map(str, order), '--jobs', '2', '--output-dir', str(outdir)])
    rows = summary(capsys.readouterr().out)
    assert code == 2
    assert sorted(p.name for p in outdir.iterdir()) == sorted(b.name for b in bags[:2])  # no partial, no bad one
    assert rows[str(bad)][:2] == ['error', '2'] and rows[str(bags[0])][:2] == ['done', '0']

    code = main(['restamp', *map(str, order), '--jobs', '2', '--suffix=-synced', '--json', '--offsets',
                 str(_saved(tmp_path, doc['bags'][0]['estimate']))])
    entries = json.loads(capsys.readouterr().out)['bags']
    assert code == 2
    assert [(e['result'], e['output']) for e in entries] == [
        ('done', f'{bags[0]}-synced'), ('error', None), ('done', f'{bags[1]}-synced')]
    assert all(e['estimate'] is None for e in entries)  # nothing estimated: the offsets were given
    for bag in bags[:2]:
        shutil.rmtree(f'{bag}-synced')


def test_exit_status_of_many_is_the_worst_bag_s(bags, tmp_path, capsys):
    """A bag of one camera (exit 1 alone) among good ones: 1; with a failing one too: 2."""
    one = tmp_path / 'one-camera'
    with BagReader(bags[0]) as reader, BagWriter(one) as writer:
        conn = next(c for c in reader.connections if c.topic == '/cam0/events')
        out = writer.add_topic(conn.topic, conn.msgtype)
        for _, timestamp, raw in reader.messages([conn.topic]):
            writer.write(out, timestamp, raw)
    assert main(['estimate', str(one)]) == 1
    assert main(['estimate', str(bags[0]), str(one)]) == 1
    capsys.readouterr()
    assert main(['estimate', str(bags[0]), str(one), str(tmp_path / 'missing')]) == 2
    rows = summary(capsys.readouterr().out)
    assert [rows[str(b)][:2] for b in (bags[0], one, tmp_path / 'missing')] == [['done', '0'], ['incomplete', '1'],
                                                                                ['error', '2']]


def test_ctrl_c_stops_every_bag_and_leaves_no_output(bags, tmp_path):
    """SIGTERM (or Ctrl-C) to the command: each running bag stopped, the rest not started, nothing
    written, exit 130. The bags' offsets come from a FIFO that is opened and never written, so that
    both running bags are certainly mid-run when the signal comes."""
    outdir = tmp_path / 'out'
    proc, writer = _restamp_waiting_for_offsets(bags, tmp_path / 'offsets.json', outdir)
    try:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=120)
    finally:
        os.close(writer)
    assert proc.returncode == 130, err
    rows = summary(out)
    assert [rows[str(b)][:1] for b in bags] == [['interrupted'], ['interrupted'], ['not']]  # not started
    assert list(outdir.iterdir()) == []  # no output, no partial


def test_a_bag_that_does_not_answer_its_sigterm_is_killed_and_the_command_ends(bags, tmp_path):
    """A bag's process that cannot take its SIGTERM (stopped here, as a hung one would be) is killed
    ``batch.STOP_GRACE_S`` after it, said on standard error, and counted interrupted: Ctrl-C never
    leaves the command waiting, nor an output behind."""
    outdir = tmp_path / 'out'
    proc, writer = _restamp_waiting_for_offsets(bags, tmp_path / 'offsets.json', outdir)
    try:
        children = Path(f'/proc/{proc.pid}/task/{proc.pid}/children')
        deadline = time.monotonic() + 60
        while len(children.read_text().split()) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        hung = int(children.read_text().split()[0])
        os.kill(hung, signal.SIGSTOP)
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=120)
    finally:
        os.close(writer)
    assert proc.returncode == 130, err
    assert batch.STOP_GRACE_S <= time.monotonic() - t0 < batch.STOP_GRACE_S + 30
    assert f'did not stop within {batch.STOP_GRACE_S:g} s of its SIGTERM; killing it' in err
    rows = summary(out)
    assert [rows[str(b)][:1] for b in bags] == [['interrupted'], ['interrupted'], ['not']]
    assert list(outdir.iterdir()) == []


def _restamp_waiting_for_offsets(bags: list[Path], fifo: Path, outdir: Path) -> tuple[subprocess.Popen[str], int]:
    """``evsync restamp BAGS --jobs 2`` whose offsets are a FIFO opened for writing and never written
    (returned, to close): both running bags certainly mid-run."""
    os.mkfifo(fifo)
    proc = subprocess.Popen([EVSYNC, 'restamp', *map(str, bags), '--jobs', '2', '--output-dir', str(outdir),
                             '--offsets', str(fifo)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return proc, _open_when_read(fifo, proc)


def _open_when_read(fifo: Path, proc: subprocess.Popen[str]) -> int:
    """The FIFO opened for writing once a bag's process has it open for reading."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            return os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        except OSError as exc:
            if exc.errno != errno.ENXIO:
                raise
            time.sleep(0.05)
    proc.kill()
    raise AssertionError(f'no bag opened the offsets: {proc.communicate()}')


@pytest.mark.parametrize(('argv', 'paths', 'options'), [
    (['estimate', '--topics', '/a', '/b', 'B1', 'B2'], ['B1', 'B2'], {'topics': ['/a', '/b']}),
    (['estimate', 'B1', '--topics', '/a', '/b', 'B2', '--json'], ['B1', 'B2'], {'topics': ['/a', '/b']}),
    (['estimate', '--latency-us', '/b=3', '--topics', '/a', '/b', 'B1', 'B2', 'B3', '-j', '2'], ['B1', 'B2', 'B3'],
     {'topics': ['/a', '/b'], 'latency_us': ['/b=3'], 'jobs': 2}),
    (['estimate', '--topics', '/a', '/b', 'B1'], ['B1'], {'topics': ['/a', '/b']}),
    (['restamp', '--topics', '/a', '/b', 'B1', 'OUT'], ['B1', 'OUT'], {'topics': ['/a', '/b']}),
    (['restamp', '--topics', '/a', '/b', 'B1', 'B2', 'B3', '--output-dir', 'D', '--jobs', '3'], ['B1', 'B2', 'B3'],
     {'topics': ['/a', '/b'], 'output_dir': 'D', 'jobs': 3}),
    (['restamp', '--suffix=-synced', '--topics', '/a', 'B1', 'B2'], ['B1', 'B2'], {'suffix': '-synced'}),
])
def test_many_bags_parse_after_many_valued_options(tmp_path, monkeypatch, argv, paths, options):
    """Bags typed after ``--topics /a /b`` are bags when they exist (a topic is no file); restamp's
    BAG OUT still takes its two (OUT need not exist)."""
    monkeypatch.chdir(tmp_path)
    for name in ('B1', 'B2', 'B3'):
        (tmp_path / name).mkdir()
    _, args = parse(argv)
    assert args.bag == paths
    for key, value in options.items():
        assert getattr(args, key) == value


def test_outputs_never_overwrite_an_input(bags, tmp_path, capsys):
    a, b = tmp_path / 'a' / 'take', tmp_path / 'b' / 'take'
    for d in (a, b):
        shutil.copytree(bags[0], d)
    assert main(['restamp', str(bags[0]), str(bags[1]), '--output-dir', str(bags[0].parent)]) == 2
    assert 'an input; nothing written' in capsys.readouterr().err
    assert main(['restamp', str(a), str(b), '--output-dir', str(tmp_path / 'out')]) == 2
    assert 'would both be written to' in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()
    assert main(['restamp', str(a), str(b), str(tmp_path / 'c')]) == 2  # three paths: not BAG OUT
    assert '--output-dir DIR or --suffix S' in capsys.readouterr().err
    plans = batch.outputs(['/x/rig.bag', '/x/rig2', str(bags[0] / 'take1.db3')], directory=None, suffix='-s')
    assert [p.output for p in plans] == ['/x/rig-s.bag', '/x/rig2-s', str(bags[0] / 'take1-s')]


def test_suffix_writes_beside_the_inputs_and_refuses_an_existing_output(bags, tmp_path, capsys):
    takes = [tmp_path / b.name for b in bags[:2]]
    for src, dst in zip(bags, takes):
        shutil.copytree(src, dst)
    (tmp_path / f'{takes[1].name}-synced').mkdir()  # already there: that bag fails, it is not written over
    assert main(['restamp', *map(str, takes), '--suffix=-synced']) == 2
    assert digest(tmp_path / f'{takes[0].name}-synced') == digest(_alone_restamp(takes[0], tmp_path / 'ref'))
    assert list((tmp_path / f'{takes[1].name}-synced').iterdir()) == []
    assert 'exists already' in capsys.readouterr().out


def _saved(folder: Path, estimate: dict) -> Path:
    path = folder / 'offsets.json'
    path.write_text(json.dumps(estimate))
    return path


def _alone_restamp(bag: Path, out: Path) -> Path:
    assert main(['restamp', str(bag), str(out)]) == 0
    return out
