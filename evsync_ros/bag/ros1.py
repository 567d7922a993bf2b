"""ROS 1 bags (``.bag``, format 2.0) through rosbags: their messages as CDR, and back.

Everything else in evsync_ros works on CDR, the bytes of a ROS 2 message. A ROS 1 message of a type
has the same layout but for two things rosbags' converters take care of: a ROS 1 ``std_msgs/Header``
begins with a ``uint32 seq`` that ROS 2 dropped, and the encodings differ in alignment. The
typestore here is built from the bag's own message definitions (the truth of its bytes), with the
ROS 2 Header in place of the ROS 1 one, as ``rosbags-convert`` does. A ROS 1 output of a ROS 1 input
keeps each message's ``seq``: what goes back to ROS 1 gets its input's first four bytes again.

``StreamingRos1`` reads a bag chunk by chunk in file order, one chunk in memory at a time (rosbags'
reader builds an index entry per message first: memory that grows with the recording).
"""

from __future__ import annotations

import bz2
import functools
import struct
from collections.abc import Callable, Iterable, Iterator, Mapping
from io import BytesIO
from pathlib import Path
from typing import Any, BinaryIO

from rosbags.interfaces import Connection, ConnectionExtRosbag1, MessageDefinition, MessageDefinitionFormat
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.base import TypesysError
from rosbags.typesys.store import Typestore

from evsync_ros.bag import records
from evsync_ros.errors import BagError
from msg_adapters.definitions import (
    EVENT_ARRAY_TYPES,
    EVENT_PACKET,
    MSG_DEFINITIONS,
    event_fielddefs,
)
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


# --- reading: chunk by chunk, with no per-message index in memory ------------------------------------

_OP_MESSAGE, _OP_BAG_HEADER, _OP_INDEX, _OP_CHUNK, _OP_CHUNK_INFO, _OP_CONNECTION = 2, 3, 4, 5, 6, 7
_DECOMPRESS: dict[str, Callable[[bytes], bytes]] = {'none': bytes, 'bz2': bz2.decompress}


def _decompressor(name: str, path: Path) -> Callable[[bytes], bytes]:
    if name == 'lz4' and name not in _DECOMPRESS:
        from lz4.frame import decompress  # type: ignore[import-untyped]  # rosbags' own dependency

        _DECOMPRESS['lz4'] = decompress
    try:
        return _DECOMPRESS[name]
    except KeyError:
        raise BagError(f'{path}: chunk compression {name!r} is not supported') from None


def _fields(blob: bytes, path: Path) -> dict[str, bytes]:
    """A record header's name=value fields."""
    out, pos = {}, 0
    while pos < len(blob):
        if pos + 4 > len(blob):
            raise BagError(f'{path}: a record header is cut short (damaged bag)')
        (size,) = struct.unpack_from('<I', blob, pos)
        pos += 4
        name, sep, value = blob[pos:pos + size].partition(b'=')
        if not sep or pos + size > len(blob):
            raise BagError(f'{path}: a record header field cannot be read (damaged bag)')
        out[name.decode(errors='replace')] = value
        pos += size
    return out


def _record(src: BinaryIO, path: Path) -> tuple[dict[str, bytes], bytes] | None:
    """The next (header fields, data) of ``src``; None at its end."""
    head = _record_head(src, path)
    if head is None:
        return None
    fields, size = head
    return fields, _record_data(src, size, path)


def _record_head(src: BinaryIO, path: Path) -> tuple[dict[str, bytes], int] | None:
    """The next record's (header fields, data length) of ``src``, which is left at its data; None at its end."""
    head = src.read(4)
    if not head:
        return None
    if len(head) < 4:
        raise BagError(f'{path}: the file ends inside a record (truncated bag)')
    (hlen,) = struct.unpack('<I', head)
    blob = src.read(hlen)
    size = src.read(4)
    if len(blob) < hlen or len(size) < 4:
        raise BagError(f'{path}: the file ends inside a record (truncated bag)')
    return _fields(blob, path), int(struct.unpack('<I', size)[0])


def _record_data(src: BinaryIO, size: int, path: Path) -> bytes:
    """A record's ``size`` bytes of data, ``src`` at them."""
    data = src.read(size)
    if len(data) < size:
        raise BagError(f'{path}: the file ends inside a record (truncated bag)')
    return data


def _op(fields: dict[str, bytes]) -> int:
    return fields.get('op', b'\xff')[0]


def _u32(fields: dict[str, bytes], name: str) -> int:
    return int(struct.unpack('<I', fields[name])[0])


def _time(value: bytes) -> int:
    sec, nsec = struct.unpack('<II', value)
    return sec * 1_000_000_000 + nsec


class StreamingRos1:
    """A ROS 1 bag read chunk by chunk in file order (the order it was recorded in), holding one chunk
    at a time: memory follows the chunk size, not the message count. ``connections`` (with message
    counts) and the time span come from the index at the end of the file; BagError naming the file
    for an unindexed, truncated or damaged bag."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.connections: list[Connection] = []
        self.start_time = self.end_time = 0
        self.message_count = 0
        self._data_start = 0
        self._index_pos = 0

    def open(self) -> None:
        p = self.path
        with p.open('rb') as src:
            if src.readline() != b'#ROSBAG V2.0\n':
                raise BagError(f'{p}: not a ROS 1 bag (format 2.0)')
            rec = _record(src, p)
            if rec is None or _op(rec[0]) != _OP_BAG_HEADER:
                raise BagError(f'{p}: no bag header record (damaged bag)')
            fields = rec[0]
            self._data_start = src.tell()
            self._index_pos = int(struct.unpack('<Q', fields['index_pos'])[0])
            if self._index_pos == 0:
                raise BagError(f'{p}: not indexed (a recorder stopped before writing its index); run '
                               '`rosbag reindex` on a copy of it')
            conns, chunks = _u32(fields, 'conn_count'), _u32(fields, 'chunk_count')
            src.seek(self._index_pos)
            found: dict[int, tuple[dict[str, bytes], dict[str, bytes]]] = {}
            counts: dict[int, int] = {}
            starts, ends = [], []
            for _ in range(conns + chunks):
                rec = _record(src, p)
                if rec is None:
                    raise BagError(f'{p}: its index is cut short (damaged bag)')
                head, data = rec
                if _op(head) == _OP_CONNECTION:
                    found[_u32(head, 'conn')] = (head, _fields(data, p))
                elif _op(head) == _OP_CHUNK_INFO:
                    n = _u32(head, 'count')
                    for k in range(n):
                        cid, cnt = struct.unpack_from('<II', data, 8 * k)
                        counts[cid] = counts.get(cid, 0) + cnt
                    if n:
                        starts.append(_time(head['start_time']))
                        ends.append(_time(head['end_time']))
        unnamed = sorted((cid, n) for cid, n in counts.items() if cid not in found and n)
        if unnamed:  # their messages would be passed over unseen: a topic gone from every output
            listed = '; '.join(f'{n} messages of connection {cid}' for cid, n in unnamed)
            raise BagError(f'{p}: its index lists {listed} but no connection record for them (damaged bag)')
        self.message_count = sum(counts.values())
        self.start_time, self.end_time = (min(starts), max(ends) + 1) if starts else (0, 0)
        for cid, (head, conn) in sorted(found.items()):
            latching = conn.get('latching', b'').decode()
            self.connections.append(Connection(
                cid, _normal_topic(head['topic'].decode()), _normal_type(conn['type'].decode()),
                MessageDefinition(MessageDefinitionFormat.MSG, conn.get('message_definition', b'').decode()),
                conn.get('md5sum', b'').decode(), counts.get(cid, 0),
                ConnectionExtRosbag1(conn['callerid'].decode() if 'callerid' in conn else None,
                                     int(latching) if latching else None), self))

    def messages(self, connections: Iterable[Connection]) -> Iterator[tuple[Connection, int, bytes]]:
        """(connection, record time, ROS 1 bytes) of ``connections``' messages, in file order."""
        by_id = {c.id: c for c in connections}
        p = self.path
        for data in self.chunks():
            inner = BytesIO(data)
            while (msg := _record(inner, p)) is not None:
                mh, raw = msg
                if _op(mh) == _OP_MESSAGE and (conn := by_id.get(_u32(mh, 'conn'))) is not None:
                    yield conn, _time(mh['time']), raw

    def chunks(self) -> Iterator[bytes | memoryview]:
        """Each chunk's records, uncompressed, in file order. An uncompressed chunk is read into one
        buffer kept from chunk to chunk (``records.read_into``): its view is good until the next
        chunk is read."""
        p = self.path
        buffer = bytearray()
        with p.open('rb') as src:
            src.seek(self._data_start)
            while src.tell() < self._index_pos:
                head = _record_head(src, p)
                if head is None:
                    raise BagError(f'{p}: the file ends before its index (truncated bag)')
                fields, size = head
                compression = fields.get('compression', b'none').decode()
                if _op(fields) != _OP_CHUNK or compression != 'none':  # index data, connections; packed chunks
                    data = _record_data(src, size, p)
                    if _op(fields) == _OP_CHUNK:
                        yield _decompressor(compression, p)(data)
                    continue
                if size > self._index_pos - src.tell():  # a damaged length: refused before memory is taken
                    raise BagError(f'{p}: a chunk is longer than the file holds before its index (damaged bag)')
                buffer, view = records.read_into(src, buffer, size)
                if len(view) < size:
                    raise BagError(f'{p}: the file ends inside a record (truncated bag)')
                yield view


def _normal_topic(topic: str) -> str:
    """A topic name without repeated slashes (as rosbags names ROS 1 topics)."""
    return '/' * topic.startswith('/') + '/'.join(part for part in topic.split('/') if part)


def _normal_type(msgtype: str) -> str:
    """ROS 1 'pkg/Name' as ROS 2's 'pkg/msg/Name'."""
    pkg, _, name = msgtype.partition('/')
    return msgtype if '/msg/' in msgtype else f'{pkg}/msg/{name}'
