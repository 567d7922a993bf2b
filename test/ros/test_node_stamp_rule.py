"""The one stamp rule, live (issue 39): copies of one real stream, each on a clock shifted by a known
offset and in an encoding of its own, through evsync_node seeded with those offsets
(``offsets_file``), come out over DDS with equal ``header.stamp`` for equal instants, the
reference's included, and consumers decode equal event times from them
(``evsync_testing.copies``; the node runs in this process, its outputs collected over real DDS:
``nodefaults.Replay``)."""

import pytest

pytest.importorskip('rclpy', reason='rclpy is installed by ./dev setup')

from evsync_testing import nodefaults
from evsync_testing.copies import davis_copies, evt3_copies, unequal_instants, with_imu
from msg_adapters.definitions import DVS_EVENT_ARRAY


@pytest.mark.parametrize('rig', ['davis', 'evt3'])
def test_copies_of_one_stream_come_out_of_the_node_with_equal_stamps_for_equal_instants(tmp_path, real_data, rig):
    copies = (davis_copies if rig == 'davis' else evt3_copies)(real_data)
    truth = {'reference': copies.reference,
             'cameras': [{'topic': t, 'encoding': 'dvs' if m == DVS_EVENT_ARRAY else 'evt3'}
                         for t, m in copies.types.items()]}
    replay = nodefaults.Replay(truth, offsets_file=str(copies.write_offsets(tmp_path / 'offsets.json')))
    try:
        replay.node.estimator.sync.freeze(True)  # the known offsets stay (as ~/freeze keeps them): the copies are exact
        replay.feed(sorted(copies.messages, key=lambda m: m[1]))
        outputs = {t: list(replay.outputs[t]) for t in copies.topics()}
        states = {t: replay.last(t)['state'] for t in copies.topics() if t != copies.reference}
    finally:
        replay.close()
    assert set(states.values()) == {'seeded'}, states
    assert {t: len(o) for t, o in outputs.items()} == {t: len(copies.of(t)) for t in copies.topics()}
    assert unequal_instants(copies, outputs) == []


@pytest.mark.parametrize('old_driver', [False, True])
def test_the_node_warns_of_a_companion_stamped_off_its_camera_s_events(tmp_path, real_data, old_driver):
    """The companion stamp check live (issue 39): an IMU stamped as libcaer_driver before 1.5.4 did
    (libcaer_driver#12) is counted and said in /diagnostics with its topic and how far off it is."""
    copies = with_imu(davis_copies(real_data), camera='/davis/events', old_driver=old_driver)
    truth = {'reference': copies.reference,
             'cameras': [{'topic': t, 'encoding': 'dvs' if m == DVS_EVENT_ARRAY else 'evt3'}
                         for t, m in copies.types.items() if t != '/davis/imu']}
    replay = nodefaults.Replay(truth, offsets_file=str(copies.write_offsets(tmp_path / 'offsets.json')),
                               companions=['/davis/imu=/davis/events'], companion_types=['sensor_msgs/msg/Imu'])
    try:
        replay.feed(sorted(copies.messages, key=lambda m: m[1]))
        imu = replay.last('/davis/imu')
        out = len(replay.outputs['/davis/imu'])
    finally:
        replay.close()
    n = len(copies.of('/davis/imu'))
    assert out == n and int(imu['messages_in']) == n  # restamped and published either way
    if not old_driver:
        assert imu['stamps_disagreeing'] == '0' and int(imu['stamps_checked']) >= n - 20, imu
        return
    assert imu['level'] == 1 and int(imu['stamps_disagreeing']) == int(imu['stamps_checked']) >= n - 20, imu
    assert imu['message'].startswith(f"/davis/imu: {imu['stamps_disagreeing']} of {imu['stamps_checked']} stamps "
                                      "disagree with /davis/events's event times by more than its packet period")
    assert 30 * 10**9 < int(imu['stamp_worst_ns']) < 32 * 10**9 and 9e6 < int(imu['packet_period_ns']) < 11e6
