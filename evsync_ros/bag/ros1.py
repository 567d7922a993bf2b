"""ROS 1 bags (``.bag``, format 2.0) through rosbags: their messages as CDR, and back.

Everything else in evsync_ros works on CDR, the bytes of a ROS 2 message. A ROS 1 message of a type
has the same layout but for two things rosbags' converters take care of: a ROS 1 ``std_msgs/Header``
begins with a ``uint32 seq`` that ROS 2 dropped, and the encodings differ in alignment. The
typestore here is built from the bag's own message definitions (the truth of its bytes), with the
ROS 2 Header in place of the ROS 1 one, as ``rosbags-convert`` does. A ROS 1 output of a ROS 1 input
keeps each message's ``seq``: what goes back to ROS 1 gets its input's first four bytes again.
Reading and writing the bag file itself: ``storage_ros1``.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Mapping
from typing import Any

from rosbags.interfaces import Connection, ConnectionExtRosbag1, MessageDefinitionFormat
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.base import TypesysError
from rosbags.typesys.store import Typestore

from evsync_ros.errors import BagError
from msg_adapters.definitions import (
    EVENT_ARRAY_TYPES,
    EVENT_PACKET,
    MSG_DEFINITIONS,
    event_fielddefs,
)
from msg_adapters.errors import MessageError
from msg_adapters.event_array import event_array_from_ros1, event_array_to_ros1
from msg_adapters.event_packet import event_packet_from_ros1, event_packet_to_ros1

SUFFIX = '.bag'
"""What a ROS 1 bag's file name ends with."""
HEADER = 'std_msgs/msg/Header'


class Unconverted(bytes):
    """A ROS 1 message that does not match its definition, as its own bytes, with why (``error``):
    what a reader yields in place of its CDR, for the front end to count and report."""

    error: str = ''


def is_ros1(path: object) -> bool:
    """Whether ``path`` names a ROS 1 bag (by its suffix: a file that need not exist yet)."""
    return str(path).endswith(SUFFIX)


def typestore_for(connections: Iterable[Connection]) -> Typestore:
    """A typestore with the ROS 2 Header and every type the connections' own (ROS 1 or ROS 2)
    definitions declare, else what evsync_ros (the event types) or ROS 2 Jazzy define of them;
    BagError naming the topic whose type is known neither way."""
    store = get_typestore(Stores.EMPTY)
    store.register(dict(header_types()))
    for conn in connections:
        if conn.msgtype in store.fielddefs:
            continue
        try:
            if not conn.msgdef.data:
                types = {}
            elif conn.msgdef.format is MessageDefinitionFormat.IDL:
                types = get_types_from_idl(conn.msgdef.data)
            else:
                types = get_types_from_msg(conn.msgdef.data, conn.msgtype)
            types.pop(HEADER, None)
            store.register(types)
        except (TypesysError, ValueError) as exc:
            try:  # a definition rosbags cannot parse: what evsync_ros or ROS 2 define of the type
                _known(store, conn)
            except (BagError, TypesysError) as known:
                raise BagError(f'topic {conn.topic}: its definition of {conn.msgtype} cannot be used ({exc}); '
                               f'{known}') from exc
        if conn.msgtype not in store.fielddefs:
            _known(store, conn)
    return store


@functools.lru_cache(maxsize=1)
def header_types() -> dict[str, Any]:
    """ROS 2's std_msgs/Header and builtin_interfaces/Time, from their definitions (ROS 2 Jazzy's
    typestore holds the same, test/bag/test_ros1.py; it takes a twentieth of a second to make)."""
    types = get_types_from_msg('int32 sec\nuint32 nanosec', 'builtin_interfaces/msg/Time')
    types.update(get_types_from_msg('builtin_interfaces/Time stamp\nstring frame_id', HEADER))
    return types


@functools.lru_cache(maxsize=1)
def _jazzy() -> Typestore:
    """ROS 2 Jazzy's typestore, made once, when a bag's type comes without a definition."""
    return get_typestore(Stores.ROS2_JAZZY)


def _known(store: Typestore, conn: Connection) -> None:
    """Register ``conn``'s type from what evsync_ros or ROS 2 Jazzy define (a bag without definitions)."""
    jazzy = _jazzy()
    if conn.msgtype in MSG_DEFINITIONS:
        types = get_types_from_msg(MSG_DEFINITIONS[conn.msgtype], conn.msgtype)
    elif conn.msgtype in jazzy.fielddefs:
        types = get_types_from_msg(jazzy.generate_msgdef(conn.msgtype, ros_version=1)[0], conn.msgtype)
    else:
        raise BagError(f'topic {conn.topic}: type {conn.msgtype} comes without a definition, and evsync_ros '
                       'knows none')
    types.pop(HEADER, None)
    store.register(types)


def is_ros1_connection(conn: Connection) -> bool:
    """Whether ``conn`` is a topic of a ROS 1 bag."""
    return isinstance(conn.ext, ConnectionExtRosbag1)


def leading_header(store: Typestore, msgtype: str) -> bool:
    """Whether messages of ``msgtype`` begin with a ``std_msgs/Header`` (their ROS 1 bytes with its seq)."""
    fields = store.fielddefs.get(msgtype, (None, []))[1]
    if not fields:
        return False
    _, desc = fields[0]
    return bool(desc[0].name == 'NAME' and desc[1] == HEADER)


def _field_defs(fielddefs: Mapping[str, Any], name: str) -> list[tuple[str, object]]:
    """A type's fields as ``fielddefs`` (a typestore's) define them, names as ROS 1 and ROS 2 both
    spell them."""
    return [(n.lower(), d) for n, d in fielddefs.get(name, (None, []))[1]]


@functools.lru_cache(maxsize=64)
def _converter(store: Typestore, msgtype: str) -> str:
    """Which of the adapters' conversions applies to ``msgtype`` as ``store`` defines it: 'array',
    'packet', or '' (rosbags' own), asked once per typestore and type (every message asks)."""
    if _fast_event_array(store, msgtype):
        return 'array'
    return 'packet' if _fast_event_packet(store, msgtype) else ''


def adapters_convert(store: Typestore, msgtype: str) -> bool:
    """Whether ``to_cdr`` and ``to_ros1`` convert ``msgtype`` with the adapters' conversions
    (``event_packet_from_ros1`` and back, ``event_array_from_ros1`` and back), not rosbags'."""
    return _converter(store, msgtype) != ''


def _fast_event_array(store: Typestore, msgtype: str) -> bool:
    """Whether ``store`` defines ``msgtype`` as the event array types evsync_ros knows (so that the
    adapters' numpy conversion applies, not rosbags' step per event)."""
    if msgtype not in EVENT_ARRAY_TYPES or msgtype not in store.fielddefs:
        return False
    known = event_fielddefs()
    event = msgtype.replace('EventArray', 'Event')
    return (_field_defs(store.fielddefs, msgtype) == _field_defs(known, msgtype)
            and _field_defs(store.fielddefs, event) == _field_defs(known, event))


def _fast_event_packet(store: Typestore, msgtype: str) -> bool:
    """Whether ``store`` defines ``msgtype`` as the EventPacket evsync_ros knows (so that the adapters'
    conversion applies, not rosbags' generated code per message)."""
    return (msgtype == EVENT_PACKET and msgtype in store.fielddefs
            and _field_defs(store.fielddefs, msgtype) == _field_defs(event_fielddefs(), msgtype))


def to_cdr(store: Typestore, raw: bytes | memoryview, msgtype: str) -> bytes:
    """A ROS 1 message as CDR (SerdeError, or MessageError for an event array, when it does not match
    its definition)."""
    converter = _converter(store, msgtype)
    if converter == 'array':
        return event_array_from_ros1(raw, what=msgtype)
    if converter == 'packet' and (cdr := event_packet_from_ros1(raw)) is not None:
        return cdr
    return bytes(store.ros1_to_cdr(raw, msgtype))


def to_ros1(store: Typestore, cdr: bytes | bytearray | memoryview, msgtype: str, *, like: bytes | None = None) -> bytes:
    """``cdr`` as ROS 1 bytes; ``like``: the input message it was made from, whose Header seq it keeps."""
    converter = _converter(store, msgtype)
    seq = int.from_bytes(like[:4], 'little') if like is not None and len(like) >= 4 else 0
    if converter == 'array':
        return event_array_to_ros1(cdr, seq=seq, what=msgtype)
    if converter == 'packet' and (ros1 := event_packet_to_ros1(cdr, seq=seq)) is not None:
        return ros1
    out = bytearray(store.cdr_to_ros1(bytes(cdr) if isinstance(cdr, bytearray) else cdr, msgtype))
    if like is not None and len(like) >= 4 and len(out) >= 4 and leading_header(store, msgtype):
        out[:4] = like[:4]
    return bytes(out)


def definition(store: Typestore, msgtype: str) -> tuple[str, str]:
    """(ROS 1 message definition, md5sum) of ``msgtype`` for a ROS 1 output: ``store``'s types with
    the ROS 1 Header (its ``seq`` included, so that ROS 1 tools compute the same md5sum)."""
    noetic = get_typestore(Stores.ROS1_NOETIC)
    defs = get_typestore(Stores.EMPTY)
    defs.register({**{k: v for k, v in store.fielddefs.items() if k != HEADER}, HEADER: noetic.fielddefs[HEADER]})
    return defs.generate_msgdef(msgtype, ros_version=1)


def converted(store: Typestore, raw: bytes, msgtype: str) -> bytes:
    """A ROS 1 message of ``msgtype`` (its own bytes) as a reader yields it: as CDR, or ``Unconverted``
    (its bytes and why) when it does not match its definition."""
    try:
        return to_cdr(store, raw, msgtype)
    except (SerdeError, MessageError) as exc:
        bad = Unconverted(raw)
        bad.error = f'does not match its definition of {msgtype} ({exc})'
        return bad
