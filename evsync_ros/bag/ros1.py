"""ROS 1 bags (``.bag``, format 2.0) through rosbags: their messages as CDR, and back.

Everything else in evsync_ros works on CDR, the bytes of a ROS 2 message. A ROS 1 message of a type
has the same layout but for two things rosbags' converters take care of: a ROS 1 ``std_msgs/Header``
begins with a ``uint32 seq`` that ROS 2 dropped, and the encodings differ in alignment. The
typestore here is built from the bag's own message definitions (the truth of its bytes), with the
ROS 2 Header in place of the ROS 1 one, as ``rosbags-convert`` does. A ROS 1 output of a ROS 1 input
keeps each message's ``seq``: what goes back to ROS 1 gets its input's first four bytes again.
"""

from __future__ import annotations

from collections.abc import Iterable

from rosbags.interfaces import Connection, ConnectionExtRosbag1, MessageDefinitionFormat
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.base import TypesysError
from rosbags.typesys.store import Typestore

from evsync_ros.errors import BagError
from msg_adapters.definitions import MSG_DEFINITIONS

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
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    store = get_typestore(Stores.EMPTY)
    store.register({HEADER: jazzy.fielddefs[HEADER], 'builtin_interfaces/msg/Time': jazzy.fielddefs[
        'builtin_interfaces/msg/Time']})
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
                _known(store, conn, jazzy)
            except (BagError, TypesysError) as known:
                raise BagError(f'topic {conn.topic}: its definition of {conn.msgtype} cannot be used ({exc}); '
                               f'{known}') from exc
        if conn.msgtype not in store.fielddefs:
            _known(store, conn, jazzy)
    return store


def _known(store: Typestore, conn: Connection, jazzy: Typestore) -> None:
    """Register ``conn``'s type from what evsync_ros or ROS 2 Jazzy define (a bag without definitions)."""
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


def to_ros1(store: Typestore, cdr: bytes | bytearray | memoryview, msgtype: str, *, like: bytes | None = None) -> bytes:
    """``cdr`` as ROS 1 bytes; ``like``: the input message it was made from, whose Header seq it keeps."""
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
