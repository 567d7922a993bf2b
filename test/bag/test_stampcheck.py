"""Companion stamps checked against their camera's event times (issue 39): an IMU stamped as
libcaer_driver before 1.5.4 stamped it (libcaer_driver#12) is warned about by ``evsync restamp``,
with its topic and how far off it is, counted, and said again by ``evsync report``; one stamped as
1.5.4 does is not. The camera is the real DAVIS346 stream (``evsync_testing.copies``)."""

import re

import numpy as np
import pytest

from evsync_ros.bag.stampcheck import CameraTimes, StampCheck
from evsync_ros.cli.main import main
from evsync_testing.copies import davis_copies, with_imu

S = 1_000_000_000


@pytest.mark.parametrize('old_driver', [False, True])
def test_restamp_warns_of_a_companion_stamped_off_its_camera_s_events_and_report_says_so(tmp_path, real_data, capsys,
                                                                                          old_driver):
    copies = with_imu(davis_copies(real_data), camera='/davis/events', old_driver=old_driver)
    bag = copies.write_bag(tmp_path / 'rig')
    offsets = copies.write_offsets(tmp_path / 'offsets.json')
    n = len(copies.of('/davis/imu'))
    assert main(['restamp', str(bag), str(tmp_path / 'out'), '--offsets', str(offsets),
                 '--companion', '/davis/imu=/davis/events']) == 0
    said = capsys.readouterr().err
    assert main(['report', str(tmp_path / 'out')]) == 0
    reported = capsys.readouterr().out
    if not old_driver:
        assert 'disagree' not in said and 'disagree' not in reported
        return
    warned = re.search(r'/davis/imu: (\d+) of (\d+) stamps disagree with /davis/events\'s event times by more than '
                       r'its packet period \((\d+\.\d) ms\), up to \+(\d+\.\d+) s', said)
    assert warned, said
    disagreeing, checked, period_ms, worst_s = warned.groups()
    assert int(disagreeing) == int(checked) >= n - 20  # every one checked once the period is known
    assert 9.0 < float(period_ms) < 11.0  # the recording's 10 ms packets
    assert 30.0 < float(worst_s) < 32.0  # 30 s of driver uptime, and growing
    assert f'warning: companion /davis/imu: {disagreeing} of {checked} stamps disagree' in reported


def test_the_check_counts_only_a_companion_clock_more_than_a_packet_period_off_the_camera_s():
    times, check = CameraTimes(), StampCheck('/imu', '/cam')
    assert check.check(5, 0, times) is None and check.checked == 0  # no period yet: nothing to judge by
    for k in range(5):  # 10 ms packets of 9 ms of events, each arriving 2 ms after its last event ...
        times.add(np.arange(k * 10, k * 10 + 9, dtype=np.int64) * 1_000_000, (k * 10 + 10) * 1_000_000)
    times.add(np.array([55_000_000]), 70_000_000)  # ... but in a quiet stretch, 15 ms after
    assert times.period_ns == 10_000_000 and times.ahead_ns(100_000_000) == -2_000_000
    ms = 1_000_000
    assert check.check(78 * ms, 100 * ms, times) is None  # a packet old, and a period more
    assert check.check(60 * ms, 100 * ms, times) is None  # delivered late: its freshest stands
    assert check.check(108 * ms, 100 * ms, times) is None  # a period ahead
    assert check.check(108 * ms + 1, 100 * ms, times) == 10 * ms + 1
    assert (check.checked, check.disagreeing, check.worst_ns, check.period_ns) == (4, 1, 10 * ms + 1, 10 * ms)
    old = StampCheck('/imu', '/cam')  # host time plus the sensor's time since the driver started
    assert old.check(3 * S + 100 * ms, 100 * ms, times) == 3 * S + 2 * ms and old.says().startswith(
        "/imu: 1 of 1 stamps disagree with /cam's event times by more than its packet period (10.0 ms), up to +3.002 s")
