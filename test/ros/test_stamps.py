"""The one stamp rule, live (issue 39): copies of one real stream, each on a clock shifted by a known
offset and in an encoding of its own, through evsync_node seeded with those offsets
(``offsets_file``), come out over DDS with equal ``header.stamp`` for equal instants, the
reference's included, and consumers decode equal event times from them
(``evsync_ros.testing.copies``; the node runs in this process, its outputs collected over real DDS:
``nodefaults.Replay``)."""

import pytest

pytest.importorskip('rclpy', reason='rclpy is installed by ./dev setup')

from evsync_ros.testing import nodefaults
from evsync_ros.testing.copies import davis_copies, evt3_copies, unequal_instants
from msg_adapters.definitions import DVS_EVENT_ARRAY


@pytest.mark.parametrize('rig', ['davis', 'evt3'])
def test_copies_of_one_stream_come_out_of_the_node_with_equal_stamps_for_equal_instants(tmp_path, real_data, rig):
    copies = (davis_copies if rig == 'davis' else evt3_copies)(real_data)
    truth = {'reference': copies.reference,
             'cameras': [{'topic': t, 'encoding': 'dvs' if m == DVS_EVENT_ARRAY else 'evt3'}
                         for t, m in copies.types.items()]}
    replay = nodefaults.Replay(truth, offsets_file=str(copies.write_offsets(tmp_path / 'offsets.json')))
    try:
        replay.node.sync.freeze(True)  # the known offsets stay (as ~/freeze keeps them): the copies are exact
        replay.feed(sorted(copies.messages, key=lambda m: m[1]))
        outputs = {t: list(replay.outputs[t]) for t in copies.topics()}
        states = {t: replay.last(t)['state'] for t in copies.topics() if t != copies.reference}
    finally:
        replay.close()
    assert set(states.values()) == {'seeded'}, states
    assert {t: len(o) for t, o in outputs.items()} == {t: len(copies.of(t)) for t in copies.topics()}
    assert unequal_instants(copies, outputs) == []
