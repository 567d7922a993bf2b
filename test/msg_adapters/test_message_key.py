"""What tells a message from every other but a second delivery of it (``header.message_key``): the same
bytes give the same key, a byte changed where event times are (its stamp, its first or last
``DUPLICATE_BYTES``) or another length gives another, and its header.stamp comes out in ns."""

from __future__ import annotations

import pytest

from evsync_testing.messages import evt3_packets
from msg_adapters.header import DUPLICATE_BYTES, message_key

NS = 1_000_000_000


def test_a_second_delivery_has_the_same_key_and_its_stamp():
    raw = evt3_packets(1, stamp_ns=1_700_000_123 * NS + 456)[0]
    key, stamp = message_key(raw)
    assert message_key(bytes(raw)) == message_key(bytearray(raw)) == (key, stamp)
    assert stamp == 1_700_000_123 * NS + 456


@pytest.mark.parametrize('at', ['stamp', 'first', 'last'])
def test_a_byte_changed_where_times_are_is_another_message(at):
    raw = bytearray(b'\x00\x01\x00\x00' + bytes(range(256)) * 8)
    i = {'stamp': 5, 'first': DUPLICATE_BYTES - 1, 'last': len(raw) - DUPLICATE_BYTES}[at]
    other = bytearray(raw)
    other[i] ^= 1
    assert message_key(raw)[0] != message_key(other)[0]
    assert message_key(raw)[0] != message_key(raw + b'\x00')[0]


def test_the_middle_is_not_read_and_a_short_message_has_no_stamp():
    raw = bytearray(b'\x00\x01\x00\x00' + bytes(range(256)) * 8)
    middle = bytearray(raw)
    middle[len(raw) // 2] ^= 1
    assert message_key(raw) == message_key(middle)
    assert message_key(b'\x00\x01\x00\x00abc')[1] is None
    assert message_key(b'')[1] is None
