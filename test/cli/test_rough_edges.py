"""Issue 39's rough edges of the command line: options before or after the bag, the demo plot's
confidence the table's, and a bag of one camera said to have nothing to synchronise; and those a user
met trying every command on the real recordings: offsets given as JSON refused as the estimate refuses
them, an output's missing folder said before anything is estimated, every command's exit status as the
README's table gives it."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest

from evsync_ros.bag.estimate import estimate_bag
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.writer import BagWriter
from evsync_ros.cli import plots, tables
from evsync_ros.cli.command import output_file
from evsync_ros.cli.main import INTERNAL_ERROR, main
from evsync_ros.errors import EvsyncError


@pytest.fixture(scope='module')
def rig(tmp_path_factory) -> tuple[Path, dict[str, Any]]:
    bag = tmp_path_factory.mktemp('rig') / 'rig'
    assert main(['simulate', str(bag), '--preset', 'same-model', '--duration', '12']) == 0
    return bag, json.loads(bag.with_name('rig.truth.json').read_text())


def _topics(truth: dict[str, Any]) -> list[str]:
    return [c['topic'] for c in truth['cameras']]


def test_estimate_takes_its_options_before_or_after_the_bag(rig, capsys):
    bag, truth = rig
    first, second = _topics(truth)[:2]
    capsys.readouterr()
    runs = []
    for argv in (['estimate', '--topics', first, second, str(bag), '--json'],
                 ['estimate', str(bag), '--topics', first, second, '--json'],
                 ['estimate', '--json', '--topics', first, second, '--latency-us', f'{second}=0', str(bag)]):
        assert main(argv) == 0, capsys.readouterr().err
        runs.append(json.loads(capsys.readouterr().out))
    assert runs[0] == runs[1]
    assert [c['topic'] for c in runs[0]['cameras']] == [c['topic'] for c in runs[2]['cameras']] == [first, second]


def test_restamp_takes_its_options_before_both_bags(rig, tmp_path, capsys):
    bag, truth = rig
    first, second = _topics(truth)[:2]
    out = tmp_path / 'out'
    assert main(['restamp', '--topics', first, second, str(bag), str(out)]) == 0, capsys.readouterr().err
    with BagReader(out) as reader:
        assert {first, second} <= {c.topic for c in reader.connections}


def test_the_demo_plot_gives_the_table_s_confidence(rig, tmp_path, monkeypatch):
    """The plot's "confidence" is the camera's, as the table prints it; the window's peak against
    its rival (a quantity of its own, 0.51 where the table said 1.000) is named apart."""
    pytest.importorskip('matplotlib', reason='plots need matplotlib (the plot extra)')
    bag, truth = rig
    est = estimate_bag(bag, reference=truth['reference'])
    titles: list[str] = []

    def keep_titles(plt: Any, fig: Any, path: Path, title: str) -> Path:
        titles.extend(ax.get_title() for ax in fig.axes)
        plt.close(fig)
        return path

    monkeypatch.setattr(plots, '_save', keep_titles)
    plots.plot(tmp_path / 'demo.png', est.rig, windows=est.windows)
    table = tables.offsets_table(est.rig)
    for cam in est.rig.cameras:
        if cam.topic == est.rig.reference:
            continue
        row = next(ln for ln in table.splitlines() if ln.startswith(cam.topic))
        in_table = row.split()[-2]  # the confidence column, before "accepted"
        said = [t for t in titles if t.startswith('D(dt)')]
        assert said, titles
        confidences = {m.group(1) for t in said for m in [re.search(r'confidence (\S+)\n', t)] if m}
        assert in_table in confidences, (in_table, said)
    assert all("window's peak against its rival" in t for t in titles if t.startswith('D(dt)'))


@pytest.fixture(scope='module')
def one_camera(rig, tmp_path_factory) -> tuple[Path, str]:
    bag, truth = rig
    topic = truth['reference']
    out = tmp_path_factory.mktemp('one') / 'one'
    with BagReader(bag) as reader, BagWriter(out) as writer:
        conn = next(c for c in reader.connections if c.topic == topic)
        mine = writer.add_topic(topic, conn.msgtype)
        for _, stamp, raw in reader.messages([topic]):
            writer.write(mine, stamp, bytes(raw))
    return out, topic


def test_estimating_a_one_camera_bag_says_there_is_nothing_to_synchronise(one_camera, capsys):
    """Exit 1 ("done, with something not accepted"): the estimate is printed as asked (the reference
    alone), and a script that checks the status sees nothing was synchronised."""
    bag, topic = one_camera
    capsys.readouterr()
    assert main(['estimate', str(bag), '--json']) == 1
    captured = capsys.readouterr()
    assert [c['topic'] for c in json.loads(captured.out)['cameras']] == [topic]
    assert str(bag) in captured.err and topic in captured.err and 'nothing to synchronise' in captured.err
    assert main(['estimate', str(bag)]) == 1
    assert 'nothing to synchronise' in capsys.readouterr().err


def test_reporting_a_one_camera_bag_says_there_is_nothing_to_synchronise(one_camera, capsys):
    """Issue 52: as estimate says it, with estimate's status (1): the report is printed as asked."""
    bag, topic = one_camera
    capsys.readouterr()
    assert main(['report', str(bag)]) == 1
    captured = capsys.readouterr()
    assert topic in captured.out and 'reference' in captured.out
    assert str(bag) in captured.err and topic in captured.err and 'nothing to synchronise' in captured.err


def test_restamping_a_one_camera_bag_is_refused_and_writes_nothing(one_camera, tmp_path, capsys):
    """Exit 2 (a clear error): a copy would change nothing, and would look restamped."""
    bag, topic = one_camera
    out = tmp_path / 'out'
    assert main(['restamp', str(bag), str(out)]) == 2
    err = capsys.readouterr().err
    assert str(bag) in err and topic in err and 'nothing to synchronise' in err and 'nothing written' in err
    assert not out.exists()


def test_a_defect_is_its_own_exit_status_with_its_traceback(one_camera, monkeypatch, capsys):
    """An exception evsync_ros does not expect (a defect, not the input's fault) exits 70 with its
    traceback, never 1, which says "done, something not accepted" (a batch of bags counts it failed)."""
    def broken(*args: Any, **kwargs: Any) -> Any:
        raise RuntimeError('a defect')

    monkeypatch.setattr('evsync_ros.bag.estimate.estimate_bag', broken)
    assert main(['estimate', str(one_camera[0]), '--json']) == INTERNAL_ERROR == 70
    err = capsys.readouterr().err
    assert 'Traceback' in err and 'RuntimeError: a defect' in err and 'internal error' in err


def _estimate_json(bag: Path, tmp_path: Path, capsys: Any, *, refuse: str | None = None) -> Path:
    """``evsync estimate BAG --json`` into a file; with ``refuse``, that camera marked not accepted."""
    capsys.readouterr()
    main(['estimate', str(bag), '--json'])
    doc = json.loads(capsys.readouterr().out)
    for cam in doc['cameras']:
        if cam['topic'] == refuse:
            cam.update(accepted=False, uncertainty_ns=None, skew_uncertainty_ppm=None, reason='windows disagree')
    path = tmp_path / f'{bag.name}-{refuse is not None}.json'
    path.write_text(json.dumps(doc))
    return path


def test_offsets_given_as_json_are_refused_as_the_estimate_refuses_them(rig, tmp_path, capsys):
    """``restamp --offsets FILE.json`` with a camera the estimate did not accept: exit 2, nothing written,
    as restamp's own estimate refuses it; with --force it is applied, said on standard error, exit 1 ("a
    camera not accepted"), and the output's provenance, which ``report OUT`` prints, says --force."""
    bag, truth = rig
    camera = _topics(truth)[1]
    given = _estimate_json(bag, tmp_path, capsys, refuse=camera)
    out = tmp_path / 'out'
    assert main(['restamp', str(bag), str(out), '--offsets', str(given)]) == 2
    err = capsys.readouterr().err
    assert str(given) in err and f'no accepted estimate for {camera}' in err and 'nothing written' in err
    assert not out.exists()
    assert main(['restamp', str(bag), str(out), '--offsets', str(given), '--force']) == 1
    assert f'--force: {camera}' in capsys.readouterr().err
    main(['report', str(out)])  # (its own estimate's status: of no concern here)
    assert 'with --force' in capsys.readouterr().out.splitlines()[0]
    accepted = _estimate_json(bag, tmp_path, capsys)
    assert main(['restamp', str(bag), str(tmp_path / 'all'), '--offsets', str(accepted)]) == 0
    rows = {line.split()[0]: line for line in capsys.readouterr().out.splitlines() if line.startswith('/')}
    assert rows[truth['reference']].endswith('as recorded (the reference: moved by 0)')  # not "moved with"


def test_offsets_given_for_a_one_camera_bag_are_refused(one_camera, tmp_path, capsys):
    bag, topic = one_camera
    given = _estimate_json(bag, tmp_path, capsys)
    out = tmp_path / 'out'
    assert main(['restamp', str(bag), str(out), '--offsets', str(given)]) == 2
    err = capsys.readouterr().err
    assert str(bag) in err and topic in err and 'nothing to synchronise' in err and 'nothing written' in err
    assert not out.exists()
    capsys.readouterr()  # onto host time, one camera is a rig
    assert main(['estimate', str(bag), '--reference', 'host', '--json']) == 0
    host = tmp_path / 'host.json'
    host.write_text(capsys.readouterr().out)
    assert main(['restamp', str(bag), str(out), '--offsets', str(host)]) == 0


def test_offsets_given_are_refused_only_when_they_correct_no_camera_of_the_bag(rig, one_camera, tmp_path, capsys):
    """A one-camera estimate on a bag of three corrects nothing: refused; --topics naming one camera
    with the JSON's reference kept restamps that camera onto it."""
    bag, truth = rig
    lone = _estimate_json(one_camera[0], tmp_path, capsys)
    assert main(['restamp', str(bag), str(tmp_path / 'none'), '--offsets', str(lone)]) == 2
    err = capsys.readouterr().err
    assert str(lone) in err and 'corrects no camera' in err and 'nothing written' in err
    assert not (tmp_path / 'none').exists()
    given = _estimate_json(bag, tmp_path, capsys)
    camera = _topics(truth)[1]
    assert main(['restamp', str(bag), str(tmp_path / 'one'), '--offsets', str(given), '--topics', camera]) == 0


@pytest.mark.parametrize('argv', [['report', '{bag}', '--plot', '{missing}/p.png'],
                                  ['verify', '{bag}', '--plot', '{missing}/v.png'],
                                  ['verify', '{bag}', '--save-latencies', '{missing}/l.json'],
                                  ['plotjuggler', '-o', '{missing}/x.xml'],
                                  ['demo', '--plot', '{missing}/d.png'],
                                  ['restamp', '{bag}', '{missing}/out']])
def test_an_output_s_missing_folder_is_a_clear_error_before_anything_is_done(rig, tmp_path, capsys, monkeypatch, argv):
    """Exit 2 naming the file, no traceback, and before the estimate (it would fail after it)."""
    def not_reached(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError('estimated before the output was checked')

    monkeypatch.setattr('evsync_ros.bag.estimate.estimate_bag', not_reached)
    monkeypatch.setattr('evsync_ros.sim.pixelsim.preset', not_reached)
    missing = tmp_path / 'no such folder'
    capsys.readouterr()
    assert main([a.format(bag=rig[0], missing=missing) for a in argv]) == 2
    err = capsys.readouterr().err
    assert str(missing) in err and 'does not exist' in err and 'Traceback' not in err


def test_an_output_file_is_checked_for_what_stands_in_its_way(tmp_path, monkeypatch):
    (tmp_path / 'a file').write_text('')
    for path, said in ((tmp_path / 'a file' / 'p.png', 'its folder'), (tmp_path, 'a folder, not a file'),
                       (tmp_path / 'a file' / 'p.png', 'is a file, not a folder'),
                       (tmp_path / 'none' / 'p.png', 'does not exist')):
        with pytest.raises(EvsyncError, match=said):
            output_file(str(path), option='--plot')
    monkeypatch.chdir(tmp_path)
    output_file('p.png', option='--plot')  # here: its folder is '.'
    output_file(None, option='--plot')


def test_a_report_of_an_estimate_json_exits_as_the_estimate_did(rig, one_camera, tmp_path, capsys):
    """README's exit statuses: 0 when every camera is accepted, 1 when one is not or the bag had one
    camera, for a report of the JSON as for the report of the bag."""
    bag, truth = rig
    assert main(['report', str(_estimate_json(bag, tmp_path, capsys))]) == 0
    assert main(['report', str(_estimate_json(bag, tmp_path, capsys, refuse=_topics(truth)[1]))]) == 1
    assert main(['report', str(_estimate_json(one_camera[0], tmp_path, capsys))]) == 1
    assert 'nothing to synchronise' in capsys.readouterr().err


def test_a_one_camera_bag_s_report_draws_its_plot_and_verify_exits_1(one_camera, tmp_path, capsys):
    """The refined method's report of one camera has no window to draw: its offset alone is drawn (as of
    its JSON), not refused as if the method were another; verify of it says there is nothing to verify."""
    pytest.importorskip('matplotlib', reason='the plots need matplotlib')
    bag, _ = one_camera
    assert main(['report', str(bag), '--plot', str(tmp_path / 'one.png')]) == 1
    assert (tmp_path / 'one.png').exists()
    capsys.readouterr()
    assert main(['verify', str(bag)]) == 1
    assert 'nothing to synchronise' in capsys.readouterr().err


def test_the_json_of_several_bags_is_refused_for_what_it_is(rig, tmp_path, capsys):
    bag = rig[0]
    capsys.readouterr()
    main(['estimate', str(bag), str(bag), '--json'])
    several = tmp_path / 'several.json'
    several.write_text(capsys.readouterr().out)
    assert main(['report', str(several)]) == 2
    err = capsys.readouterr().err
    assert str(several) in err and 'several bags' in err and 'KeyError' not in err


def test_a_bag_too_short_for_the_host_clock_is_named_with_what_it_needs(one_camera, tmp_path, capsys):
    bag, topic = one_camera
    short = tmp_path / 'short'
    with BagReader(bag) as reader, BagWriter(short) as writer:
        conn = next(c for c in reader.connections if c.topic == topic)
        mine = writer.add_topic(topic, conn.msgtype)
        for i, (_, stamp, raw) in enumerate(reader.messages([topic])):
            if i == 0:
                first = stamp
            if stamp - first < 1_000_000_000:
                writer.write(mine, stamp, bytes(raw))
    capsys.readouterr()
    assert main(['estimate', str(short), '--reference', 'host']) == 2
    err = capsys.readouterr().err
    assert str(short) in err and 'host clock needs messages in' in err and 'segments' not in err


def test_events_outside_the_geometry_are_said_with_what_becomes_of_them(real_data, capsys):
    """person_far's right camera has 28 events outside its 128x128 (its README counts them with the
    rest): said as counted, not used by the estimate, kept by a restamp."""
    main(['estimate', str(real_data / 'dvs128_stereo' / 'person_far')])
    line = next(line for line in capsys.readouterr().err.splitlines() if 'counted while decoding' in line)
    assert 'outside the sensor geometry x' in line and 'not used by the estimate; a restamp keeps them' in line


def _drawn(calls: list[tuple[int, int]], **kwargs: Any) -> list[str]:
    """The lines a progress bar draws for ``calls``."""
    import io

    from evsync_ros.cli.progress import Progress

    stream = io.StringIO()
    bar = Progress('estimating rig', stream=stream, force=True, every_s=0.0, **kwargs)
    for done, total in calls:
        bar(done, total)
    bar.close()
    return [line.rstrip() for line in stream.getvalue().strip('\n').split('\r') if line]


def test_the_progress_bar_never_falls_back_when_a_second_pass_adds_to_the_total():
    """Issue 52: the estimate's second pass over a drifting camera grew the total mid-run (54 % fell
    to 68 % of more); each pass now has its bar, its total known as it begins."""
    first = [(k, 1000) for k in range(0, 1001, 250)]
    second = [(1000 + k, 1600) for k in range(0, 601, 150)]
    lines = _drawn(first + second)
    percents = [int(re.search(r'(\d+)%', line).group(1)) for line in lines]
    assert percents == [0, 25, 50, 75, 100, 0, 25, 50, 75, 100], lines
    assert all('pass 2' in line for line in lines[5:]) and not any('pass' in line for line in lines[:5])
    assert '600/600 messages' in lines[-1]


def test_a_stretch_of_guessed_size_spins_rather_than_claim_a_percentage():
    lines = _drawn([(k, 500) for k in range(0, 801, 200)], exact=False)
    assert lines and not any('%' in line for line in lines) and '800 messages' in lines[-1]
