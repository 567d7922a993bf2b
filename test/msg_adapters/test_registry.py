"""The registry picks the adapter by type name and refuses what is not an event type."""

import pytest

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.errors import MessageError
from evsync_testing.messages import NS, array_bytes, packet_bytes
from msg_adapters.event_array import EventArrayDecoder
from msg_adapters.event_packet import EventPacketDecoder, PacketView
from msg_adapters.registry import decoder_for, is_event_type, restamp


def test_types_by_either_spelling():
    assert isinstance(decoder_for('event_camera_msgs/EventPacket'), EventPacketDecoder)
    assert isinstance(decoder_for('dvs_msgs/msg/EventArray'), EventArrayDecoder)
    assert isinstance(decoder_for('prophesee_event_msgs/EventArray'), EventArrayDecoder)
    assert is_event_type('dvs_msgs/EventArray') and not is_event_type('sensor_msgs/msg/Imu')


def test_restamp_dispatches_by_type():
    c = ClockCorrection(offset_ns=NS)
    dvs = 'dvs_msgs/msg/EventArray'
    _, ev = decoder_for(dvs).decode(restamp(array_bytes(dvs, [5 * NS]), dvs, c))
    assert ev.t.tolist() == [6 * NS]
    view, _ = decoder_for('event_camera_msgs/msg/EventPacket').decode(
        restamp(packet_bytes('mono', b'', time_base=NS), 'event_camera_msgs/msg/EventPacket', c))
    assert isinstance(view, PacketView) and view.time_base == 2 * NS


def test_other_types_are_refused_by_name():
    with pytest.raises(MessageError, match="'sensor_msgs/msg/Imu' is not an event message type"):
        decoder_for('sensor_msgs/msg/Imu')
    with pytest.raises(MessageError, match='sensor_msgs/msg/Imu'):
        restamp(b'', 'sensor_msgs/msg/Imu', ClockCorrection())
