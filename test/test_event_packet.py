"""EventPacket fields read straight from CDR agree with rosbags; malformed bytes get clear errors."""

import numpy as np
import pytest

from evsync_ros.bagio import BagReader
from evsync_ros.errors import MessageError
from msg_adapters.definitions import EVENT_PACKET, event_typestore
from msg_adapters.event_packet import parse_event_packet


@pytest.mark.parametrize('bag', ['evt3_sqlite3', 'libcaer_cmp_mcap'])
def test_fields_agree_with_rosbags_on_every_real_message(real_data, bag):
    store = event_typestore()
    with BagReader(real_data / bag) as reader:
        for _, _, raw in reader.messages():
            msg = store.deserialize_cdr(raw, EVENT_PACKET)
            view = parse_event_packet(raw)
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            assert (view.stamp_ns, view.frame_id, view.height, view.width, view.seq, view.time_base,
                    view.encoding, view.is_bigendian) == (
                stamp, msg.header.frame_id, msg.height, msg.width, msg.seq, msg.time_base,
                msg.encoding, msg.is_bigendian)
            np.testing.assert_array_equal(view.events, msg.events)
            assert int.from_bytes(raw[view.time_base_offset:view.time_base_offset + 8], 'little') == msg.time_base


def _serialized(**fields):
    store = event_typestore()
    Time = store.types['builtin_interfaces/msg/Time']
    Header = store.types['std_msgs/msg/Header']
    Packet = store.types[EVENT_PACKET]
    msg = Packet(header=Header(stamp=Time(sec=5, nanosec=7), frame_id='cam'), height=2, width=3, seq=1,
                 time_base=9, encoding='mono', is_bigendian=False, events=np.zeros(16, np.uint8))
    for k, v in fields.items():
        setattr(msg, k, v)
    return bytes(store.serialize_cdr(msg, EVENT_PACKET))


def test_every_truncation_is_a_clear_error():
    raw = _serialized()
    assert parse_event_packet(raw).events.size == 16
    for cut in range(len(raw)):
        with pytest.raises(MessageError, match='EventPacket'):
            parse_event_packet(raw[:cut])


def test_big_endian_cdr_is_refused():
    raw = bytearray(_serialized())
    raw[1] = 0x00  # CDR_BE representation identifier
    with pytest.raises(MessageError, match='little-endian'):
        parse_event_packet(bytes(raw))
