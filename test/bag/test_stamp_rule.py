"""The one stamp rule, offline (issue 39): copies of one real stream, each on a clock shifted by a
known offset and in an encoding of its own, restamped by ``evsync restamp --offsets`` with those
offsets, come out with equal ``header.stamp`` for equal instants, the reference's included, and
consumers decode equal event times from them (``evsync_testing.copies``)."""

import pytest

from evsync_ros.bag.reader import BagReader
from evsync_ros.cli.main import main
from evsync_testing.copies import davis_copies, evt3_copies, unequal_instants


def outputs(bag):
    with BagReader(bag) as reader:
        out: dict[str, list[bytes]] = {}
        for conn, _, raw in reader.messages():
            out.setdefault(conn.topic, []).append(bytes(raw))
        return out


@pytest.mark.parametrize('rig', ['davis', 'evt3'])
def test_copies_of_one_stream_come_out_with_equal_stamps_for_equal_instants(tmp_path, real_data, rig):
    copies = (davis_copies if rig == 'davis' else evt3_copies)(real_data)
    bag = copies.write_bag(tmp_path / 'rig')
    assert unequal_instants(copies, outputs(bag))  # as recorded: the arrival lags show
    offsets = copies.write_offsets(tmp_path / 'offsets.json')
    assert main(['restamp', str(bag), str(tmp_path / 'out'), '--offsets', str(offsets)]) == 0
    assert unequal_instants(copies, outputs(tmp_path / 'out')) == []
