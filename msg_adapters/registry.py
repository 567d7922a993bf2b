"""Which adapter serves which message type: a decoder per stream, and restamping by type name."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from msg_adapters.definitions import DVS_EVENT_ARRAY, EVENT_PACKET, EVENT_TYPES, PROPHESEE_EVENT_ARRAY
from msg_adapters.edges import TriggerEdges
from msg_adapters.errors import MessageError
from msg_adapters.event_array import (
    EventArrayDecoder,
    restamp_event_array,
    restamp_event_array_ros1,
    restamp_event_array_stamped,
    restamp_event_arrays_stamped,
)
from msg_adapters.event_packet import (
    EventPacketDecoder,
    EventPacketStreamRestamper,
    restamp_event_packet,
)
from msg_adapters.events import Anomalies
from msg_adapters.protocols import Bytes, Correction


def normalise_type(msgtype: str) -> str:
    """'pkg/msg/Type' for 'pkg/msg/Type' or 'pkg/Type'."""
    parts = msgtype.split('/')
    if len(parts) == 2:
        return f'{parts[0]}/msg/{parts[1]}'
    return msgtype


def is_event_type(msgtype: str) -> bool:
    """Whether ``msgtype`` ('pkg/msg/Type' or 'pkg/Type') is an event message type the adapters read."""
    return normalise_type(msgtype) in EVENT_TYPES


def camera_model(msgtype: str, view: object) -> str:
    """What tells camera models apart in a stream's messages, from one decoded message's fields: its
    type, encoding and geometry (the same words offline and live)."""
    return (f'{normalise_type(msgtype)} {getattr(view, "encoding", "")} '
            f'{getattr(view, "width", 0)}x{getattr(view, "height", 0)}')


def decoder_for(msgtype: str) -> EventPacketDecoder | EventArrayDecoder:
    """A fresh decoder for one stream of ``msgtype``; its ``decode(raw, xyp=...)`` returns
    (the message's fields, Events), state carrying from message to message.

    Raises:
        MessageError: ``msgtype`` is not an event message type.
    """
    name = normalise_type(msgtype)
    if name == EVENT_PACKET:
        return EventPacketDecoder()
    if name in (DVS_EVENT_ARRAY, PROPHESEE_EVENT_ARRAY):
        return EventArrayDecoder(what=name)
    raise MessageError(f"'{msgtype}' is not an event message type evsync_ros reads ({', '.join(EVENT_TYPES)})")


@dataclass(frozen=True)
class StreamEdges:
    """A stream's trigger edges (``stream_edges``), and what could not be read."""

    edges: TriggerEdges
    """Every edge of the stream, in stream order, on its events' timeline."""
    messages: int
    undecodable: int
    """Messages the decoder refused (``MessageError``), passed over: their edges are not in ``edges``."""
    first_error: str | None
    anomalies: Anomalies
    """What the decoder counted (edges it could not place among them)."""


def stream_edges(raws: Iterable[Bytes], msgtype: str) -> StreamEdges:
    """Every trigger edge of one stream's messages (serialized, in stream order), decoded as a fresh
    ``decoder_for(msgtype)`` decodes them (evt3 state and anchor carried across messages).

    Raises:
        MessageError: ``msgtype`` is not an event message type.
    """
    decoder = decoder_for(msgtype)
    parts: list[TriggerEdges] = []
    messages = undecodable = 0
    first_error: str | None = None
    for raw in raws:
        messages += 1
        try:
            _, edges = decoder.decode_times_edges(raw)
        except MessageError as exc:
            undecodable += 1
            first_error = first_error or str(exc)
            continue
        if len(edges):
            parts.append(edges)
    return StreamEdges(TriggerEdges.concatenate(parts), messages, undecodable, first_error, decoder.anomalies)


def restamp(raw: bytes | bytearray | memoryview, msgtype: str, correction: Correction) -> bytearray:
    """A corrected copy of one serialized event message (what moves per type: docs/messages.md).

    For streams, ``Restamper`` keeps what a drifting evt3 stream needs from message to message.

    Raises:
        MessageError: not an event type, the bytes do not hold one, or a corrected time leaves its field.
    """
    name = normalise_type(msgtype)
    if name == EVENT_PACKET:
        return restamp_event_packet(raw, correction)
    if name in (DVS_EVENT_ARRAY, PROPHESEE_EVENT_ARRAY):
        return restamp_event_array(raw, correction, what=name)
    raise MessageError(f"'{msgtype}' is not an event message type evsync_ros restamps ({', '.join(EVENT_TYPES)})")


class Restamper:
    """Restamps one stream's messages in stream order, the reference's too (with no correction), so
    that ``header.stamp`` means one thing in every output: the time of the message's first event
    on the rig's timeline, as a consumer decodes it (a message without events: its own stamp,
    corrected; docs/messages.md). For evt3 the stamp and the time words agree, so that a consumer
    anchoring at any message decodes every event on the rig's timeline; the correction may change
    from message to message (``event_packet.EventPacketStreamRestamper``).

    ``live``: kept for callers; a bag's stream and a live one are restamped alike.
    """

    def __init__(self, msgtype: str, *, live: bool = False) -> None:
        if not is_event_type(msgtype):
            raise MessageError(f"'{msgtype}' is not an event message type evsync_ros restamps "
                               f"({', '.join(EVENT_TYPES)})")
        self.msgtype = msgtype
        self.live = live
        self._packets = EventPacketStreamRestamper() if normalise_type(msgtype) == EVENT_PACKET else None

    @property
    def packets(self) -> EventPacketStreamRestamper | None:
        """An EventPacket stream's restamper (what ``EventPacketDecoder.step`` restamps with); None for
        an EventArray stream."""
        return self._packets

    def restamp(self, raw: bytes | bytearray | memoryview, correction: Correction) -> bytearray:
        """The next message of the stream, corrected (MessageError as ``restamp``)."""
        if self._packets is not None:
            return self._packets.restamp(raw, correction)
        return restamp_event_array_stamped(raw, correction, what=normalise_type(self.msgtype))

    def restamp_rows(self, chunk: bytes | memoryview, rows: npt.NDArray[np.int64], start: int,
                     correction: Correction, *, stamps: npt.NDArray[np.int64],
                     new: list[bytes | bytearray | None], ros1: bool = False) -> int:
        """The stream's next messages, those of ``chunk`` that ``rows`` point to (int64 rows: data
        offset and length, then two more columns) from row ``start`` on, restamped in one C call for
        as long as the C path takes each: an evt3 packet's new header.stamp into ``stamps`` (the rest
        of it unchanged) or, where its time words move, the retimed packet into ``new``; an
        EventArray's copy into ``new``; with ``ros1`` the messages are ROS 1
        bytes, restamped as ``restamp_ros1`` restamps them. Returns the first row it leaves, the
        stream's state as before it, for ``restamp`` (``restamp_ros1``) (``len(rows)``: none left)."""
        if self._packets is not None:
            return self._packets.restamp_rows(chunk, rows, start, correction, stamps, new, ros1=ros1)
        return restamp_event_arrays_stamped(chunk, rows, start, correction, new, ros1=ros1)

    def restamp_ros1(self, raw: bytes | bytearray | memoryview, correction: Correction) -> bytearray | None:
        """The next message of the stream given as ROS 1 bytes (converted as ``event_packet_from_ros1``
        converts), corrected, as ROS 1 bytes, where the adapters do that without converting (a plain
        evt3 EventPacket: ``EventPacketStreamRestamper.restamp_ros1``; an EventArray:
        ``event_array.restamp_event_array_ros1``); None for any other message, nothing moved: convert
        it and call ``restamp``."""
        if self._packets is None:
            return restamp_event_array_ros1(raw, correction)
        return self._packets.restamp_ros1(raw, correction)
