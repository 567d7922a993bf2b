"""event_camera_msgs/EventPacket straight from CDR bytes: fields, decoding per encoding, restamping.

CDR field order (see ``cdr.py`` for alignment):

    header.stamp.sec int32, header.stamp.nanosec uint32, header.frame_id string,
    height uint32, width uint32, seq uint64, time_base uint64, encoding string,
    is_bigendian bool, events uint8[] (uint32 length, then the bytes)

Which times each encoding's events carry, what restamping moves, and how evt3's sensor time is
anchored to ROS time: docs/messages.md."""

from __future__ import annotations

import struct
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from msg_adapters import _kernels
from msg_adapters.cdr import (
    FRAME_ID_OFFSET,
    MAX_TIME_NS,
    align,
    check_encapsulation,
    read_stamp,
    read_string,
    write_stamp,
)
from msg_adapters.edges import TriggerEdges
from msg_adapters.errors import MessageError
from msg_adapters.events import Anomalies, Events, Stepped
from msg_adapters.evt3 import Evt3Decoder, Evt3Retimer
from msg_adapters.libcaer import LibcaerDecoder
from msg_adapters.libcaer_cmp import LibcaerCmpDecoder
from msg_adapters.mono import MonoDecoder
from msg_adapters.protocols import Correction
from msg_adapters.trigger import TriggerDecoder

ENCODINGS = ('evt3', 'libcaer_cmp', 'libcaer', 'mono', 'trigger')
REANCHOR_NS = 1_000_000_000
"""An evt3 stream whose header.stamp and sensor time disagree by more than this re-anchors."""
_WHAT = 'EventPacket'


SEQ_GAP = 'messages missing (seq gap)'
"""The anomaly counted for messages missing from a stream's seq (lost before the decoder saw them)."""
UNANCHORED_EDGE = "trigger edge before the stream's first event (no anchor to place it on)"
"""The anomaly counted for evt3 trigger edges in messages before the stream's first event: their
sensor time has no anchor yet (docs/messages.md)."""

class PacketView(NamedTuple):
    """An EventPacket's fields, and where the time fields sit in the serialized bytes."""

    stamp_ns: int
    frame_id: str
    height: int
    width: int
    seq: int
    time_base: int
    encoding: str
    is_bigendian: bool
    events: np.ndarray
    """The payload as a uint8 view into the message bytes."""
    time_base_offset: int
    """Where the uint64 time_base sits in the serialized bytes (it follows a variable-length frame_id)."""


_LAST_PARSED: list[tuple[bytes, PacketView] | None] = [None]
"""The last ``bytes`` object parsed and its view: a live stream's message is decoded, then restamped,
each of which parses it (bytes are immutable, so the same object has the same fields)."""


def parse_event_packet(raw: bytes | bytearray | memoryview) -> PacketView:
    """Read an EventPacket's CDR bytes; MessageError when they do not hold one."""
    last = _LAST_PARSED[0]
    if last is not None and last[0] is raw:
        return last[1]
    view = _parse(raw)
    if type(raw) is bytes:
        _LAST_PARSED[0] = (raw, view)
    return view


_FIXED = struct.Struct('<2s2xiII')
"""Encapsulation id, header.stamp (sec, nanosec) and the length of header.frame_id (at byte 12)."""
_SEQ_TIME_BASE_ENCODING = struct.Struct('<QQI')
_NS = 1_000_000_000


def _parse(raw: bytes | bytearray | memoryview) -> PacketView:
    """``_parse_checked``'s fields, read with a few unpacks for a well-formed packet; anything else
    goes to ``_parse_checked``, whose error names what is wrong (the same view either way)."""
    n = len(raw)
    if n < 16:
        return _parse_checked(raw)
    rep, sec, nanosec, frame_len = _FIXED.unpack_from(raw, 0)
    pos = 16 + frame_len
    if rep not in (b'\x00\x01', b'\x00\x03') or frame_len == 0 or pos > n:
        return _parse_checked(raw)
    frame_id = str(raw[16:pos - 1], 'utf-8', 'replace')
    pos += -(pos - 4) % 4
    if pos + 8 > n:
        return _parse_checked(raw)
    height, width = struct.unpack_from('<II', raw, pos)
    pos += 8
    pos += -(pos - 4) % 8
    if pos + 20 > n:
        return _parse_checked(raw)
    seq, time_base, encoding_len = _SEQ_TIME_BASE_ENCODING.unpack_from(raw, pos)
    time_base_offset = pos + 8
    pos += 20
    if encoding_len == 0 or pos + encoding_len + 1 > n:
        return _parse_checked(raw)
    encoding = str(raw[pos:pos + encoding_len - 1], 'utf-8', 'replace')
    pos += encoding_len
    is_bigendian = raw[pos] != 0
    pos += 1
    pos += -(pos - 4) % 4
    if pos + 4 > n:
        return _parse_checked(raw)
    (n_bytes,) = struct.unpack_from('<I', raw, pos)
    pos += 4
    if pos + n_bytes > n:
        return _parse_checked(raw)
    return PacketView(sec * _NS + nanosec, frame_id, height, width, seq, time_base, encoding, is_bigendian,
                      np.frombuffer(raw, dtype=np.uint8, count=n_bytes, offset=pos), time_base_offset)


def _parse_checked(raw: bytes | bytearray | memoryview) -> PacketView:
    """An EventPacket's fields, each step checked: MessageError naming the first that is wrong."""
    check_encapsulation(raw, _WHAT)
    frame_id, pos = read_string(raw, FRAME_ID_OFFSET, 'header.frame_id', _WHAT)
    pos = align(pos, 4)
    if pos + 8 > len(raw):
        raise MessageError('EventPacket truncated before height/width')
    height, width = struct.unpack_from('<II', raw, pos)
    pos = align(pos + 8, 8)
    if pos + 16 > len(raw):
        raise MessageError('EventPacket truncated before seq/time_base')
    seq, time_base = struct.unpack_from('<QQ', raw, pos)
    time_base_offset = pos + 8
    encoding, pos = read_string(raw, pos + 16, 'encoding', _WHAT)
    if pos + 1 > len(raw):
        raise MessageError('EventPacket truncated before is_bigendian')
    is_bigendian = raw[pos] != 0
    pos = align(pos + 1, 4)
    if pos + 4 > len(raw):
        raise MessageError('EventPacket truncated before the events length')
    (n_bytes,) = struct.unpack_from('<I', raw, pos)
    pos += 4
    if pos + n_bytes > len(raw):
        raise MessageError(f'EventPacket truncated: events declares {n_bytes} bytes, {len(raw) - pos} present')
    return PacketView(
        stamp_ns=read_stamp(raw),
        frame_id=frame_id,
        height=height,
        width=width,
        seq=seq,
        time_base=time_base,
        encoding=encoding,
        is_bigendian=is_bigendian,
        events=np.frombuffer(raw, dtype=np.uint8, count=n_bytes, offset=pos),
        time_base_offset=time_base_offset,
    )


def _check_encoding(view: PacketView) -> None:
    if view.encoding not in ENCODINGS:
        raise MessageError(f"EventPacket encoding '{view.encoding}' is not one of {', '.join(ENCODINGS)}")
    if view.is_bigendian:
        raise MessageError(f"EventPacket ({view.encoding}) has is_bigendian set: big-endian payloads are not supported")


def _moves_time_base(view: PacketView) -> bool:
    return view.encoding != 'evt3' or view.time_base != 0


_Codec = Evt3Decoder | LibcaerCmpDecoder | LibcaerDecoder | MonoDecoder | TriggerDecoder
TimeBaseStep = LibcaerCmpDecoder | LibcaerDecoder | MonoDecoder
"""The decoders of the encodings whose live messages ``EventPacketDecoder.step`` takes in one C call
and restamps by their time_base (a union ``isinstance`` takes as it is)."""


def _new_codec(view: PacketView) -> _Codec:
    """The payload decoder of a stream whose first message is ``view``."""
    if view.encoding == 'evt3':
        return Evt3Decoder(width=view.width, height=view.height)
    if view.encoding == 'libcaer_cmp':
        return LibcaerCmpDecoder(width=view.width, height=view.height)
    if view.encoding == 'libcaer':
        return LibcaerDecoder(width=view.width, height=view.height)
    if view.encoding == 'mono':
        return MonoDecoder(width=view.width, height=view.height)
    return TriggerDecoder()


class EventPacketDecoder:
    """One stream's EventPacket messages to event times on the camera's timeline (int64 ns).

    The first message fixes the stream's encoding and geometry; decoder state (evt3 time words,
    libcaer overflow carry, current coordinates) carries from message to message. MessageError
    for a message that cannot be decoded (the stream's state is left as it was); anything that
    can be decoded but is odd is counted in ``anomalies``.
    """

    def __init__(self) -> None:
        self.encoding: str | None = None
        self.width = self.height = 0
        self.anchor_ns: int | None = None
        """evt3 only: ROS time minus sensor time, from header.stamp (see the module docstring)."""
        self._codec: _Codec | None = None
        self._last_seq: int | None = None
        self._last_t: int | None = None
        self._own = Anomalies()
        self.lost = 0
        """Messages missing from the stream's seq so far (lost before the decoder saw them)."""

    @property
    def anomalies(self) -> Anomalies:
        """This stream's counted anomalies, the codec's and the stream's own."""
        merged = Anomalies(self._own)
        if self._codec is not None:
            for name, n in self._codec.anomalies.items():
                merged.count(name, n)
        return merged

    def decode(self, raw: bytes | bytearray | memoryview, *, xyp: bool = False) -> tuple[PacketView, Events]:
        """The next message of the stream: its fields and its events (times in int64 ns on the
        camera's timeline; x, y, polarity too with ``xyp``).

        Raises:
            MessageError: the bytes do not hold an EventPacket, the encoding is unknown or big-endian,
                or the stream changed encoding or geometry; the stream's state is left as it was.
        """
        view, codec = self._accept(raw)
        if isinstance(codec, Evt3Decoder):
            events = codec.decode(view.events, xyp=xyp)
            self._to_ros_time(view, events.t)
        else:
            events = codec.decode(view.events, time_base=view.time_base, xyp=xyp)
        self._went_on(events.t)
        return view, events

    def decode_edges(self, raw: bytes | bytearray | memoryview, *, xyp: bool = False
                     ) -> tuple[PacketView, Events, TriggerEdges]:
        """``decode``, and the message's trigger edges on the same timeline as its events (evt3
        EXT_TRIGGER words, anchored as the events are; the ``trigger`` encoding's edges; none for
        the other encodings), from the same walk of the payload. The stream's state moves on as
        ``decode`` moves it, so a stream's messages may go to either, in order.

        Raises:
            MessageError: as ``decode``.
        """
        view, codec = self._accept(raw)
        if isinstance(codec, Evt3Decoder):
            events, edges = codec.decode_edges(view.events, xyp=xyp)
            self._to_ros_time(view, events.t)
            edges = self._place_edges(edges, view.time_base)
        elif isinstance(codec, TriggerDecoder):
            events, edges = codec.decode_edges(view.events, time_base=view.time_base, xyp=xyp)
        else:
            events, edges = codec.decode(view.events, time_base=view.time_base, xyp=xyp), TriggerEdges.empty()
        self._went_on(events.t)
        return view, events, edges

    def decode_times_edges(self, raw: bytes | bytearray | memoryview
                           ) -> tuple[npt.NDArray[np.int64], TriggerEdges]:
        """``decode_edges(raw)``'s event times and edges, by the quickest way there is (a plain evt3
        packet: one C call, as ``decode_times``).

        Raises:
            MessageError: as ``decode``.
        """
        codec = self._codec
        if isinstance(codec, Evt3Decoder):
            got = codec.decode_packet_edges(raw)
            if got is not None:
                events, edges, stamp_ns, seq = got
                self._check_seq(seq)
                self._anchor(stamp_ns, events.t)
                self._went_on(events.t)
                return events.t, self._place_edges(edges, 0)
        _, events, edges = self.decode_edges(raw)
        return events.t, edges

    def _accept(self, raw: bytes | bytearray | memoryview) -> tuple[PacketView, _Codec]:
        """The message's fields and the stream's codec, after the checks every message passes (the
        first fixes the stream's encoding and geometry); its seq counted.

        Raises:
            MessageError: as ``decode``.
        """
        view = parse_event_packet(raw)
        _check_encoding(view)
        if view.time_base > MAX_TIME_NS:
            raise MessageError(f'EventPacket time_base {view.time_base} ns is later than any ROS time (2^31 s)')
        codec = self._codec
        if codec is None:
            self.encoding, self.width, self.height = view.encoding, view.width, view.height
            codec = self._codec = _new_codec(view)
        elif (view.encoding, view.width, view.height) != (self.encoding, self.width, self.height):
            raise MessageError(
                f'EventPacket stream changed from {self.encoding} {self.width}x{self.height} '
                f'to {view.encoding} {view.width}x{view.height} in mid-stream')
        self._check_seq(view.seq)
        return view, codec

    def _place_edges(self, edges: TriggerEdges, time_base: int) -> TriggerEdges:
        """An evt3 message's edges (sensor times) onto the timeline its events went to: ``time_base``
        when it has one, else the stream's anchor; before the stream has one they are counted."""
        if not len(edges):
            return edges
        shift = time_base or self.anchor_ns
        if shift is None:
            self._own.count(UNANCHORED_EDGE, len(edges))
            return TriggerEdges.empty()
        np.add(edges.t, np.int64(shift), out=edges.t)  # the decoder's copy, ours to move
        return edges

    def decode_times(self, raw: bytes | bytearray | memoryview) -> npt.NDArray[np.int64]:
        """``decode(raw)[1].t``: the same times, state and anomalies, without the message's fields. An
        evt3 stream's plain packet (``Evt3Decoder.decode_packet``) is decoded in one C call.

        Raises:
            MessageError: as ``decode``.
        """
        times = self._plain_times(raw, ros1=False)
        return self.decode(raw)[1].t if times is None else times

    def decode_ros1_times(self, raw: bytes | bytearray | memoryview) -> npt.NDArray[np.int64] | None:
        """A ROS 1 EventPacket's times, state and anomalies as ``decode_times`` gives them of its CDR
        (``event_packet_from_ros1``), when that is a plain evt3 packet (``Evt3Decoder.decode_packet``):
        no conversion. None, nothing moved, for any other message, to be converted and decoded."""
        return self._plain_times(raw, ros1=True)

    def _plain_times(self, raw: bytes | bytearray | memoryview, *, ros1: bool) -> npt.NDArray[np.int64] | None:
        codec = self._codec
        if not isinstance(codec, Evt3Decoder):
            return None
        got = codec.decode_packet(raw, ros1=ros1)
        if got is None:
            return None
        events, stamp_ns, seq = got
        self._check_seq(seq)
        self._anchor(stamp_ns, events.t)
        self._went_on(events.t)
        return events.t

    def step(self, raw: bytes | bytearray | memoryview, *, grid_ns: int, counts: npt.NDArray[np.int32],
             restamper: EventPacketStreamRestamper | None, correction: Correction | None,
             edges: bool = False) -> Stepped | None:
        """A live evt3 stream's next message in one C call (``Evt3Decoder.packet_step``): decoded as
        ``decode_times`` decodes it (with ``edges``: as ``decode_times_edges``, its edges too), counted
        on the grid of ``grid_ns`` (into ``counts``) and, given a ``restamper`` and a ``correction``,
        restamped as ``restamper.restamp`` restamps it. None for any message that call does not take
        (another encoding, a packet not plain, the stream's first), nothing moved: decode and restamp
        it apart."""
        codec = self._codec
        if isinstance(codec, TimeBaseStep):
            return self._time_base_step(codec, raw, grid_ns, counts, restamper, correction, edges)
        if not isinstance(codec, Evt3Decoder):
            return None
        c = (0.0, 0, 0) if correction is None else (correction.skew_ppm * 1e-6, correction.offset_ns,
                                                    correction.anchor_ns)
        retimer = None if restamper is None or correction is None else restamper.retimer
        got = codec.packet_step(raw, anchor=self.anchor_ns, grid_ns=grid_ns, counts=counts, retimer=retimer,
                                correction=c, edges=edges)
        if got is None:
            return None
        (n, _, seq, anchor, lo, hi, mid, k0, nbins, out, restamped, _), t, found = got
        self._check_seq(seq)
        if n:  # as ``_plain_times`` after its ``_anchor``
            self._anchored(anchor)
            self._went_on(t[:n])
        placed = self._place_edges(found, 0) if found is not None else None
        error = ''
        if restamped is not None:  # its stamp out of range, or a packet to encode here
            try:
                out = EventPacketStreamRestamper.written(raw, restamped)
            except MessageError as exc:
                error = str(exc)
        return Stepped(t[:n], lo, hi, mid, k0, counts[:nbins] if nbins >= 0 else None, out, error, placed)

    def _time_base_step(self, codec: TimeBaseStep, raw: bytes | bytearray | memoryview, grid_ns: int,
                        counts: npt.NDArray[np.int32], restamper: EventPacketStreamRestamper | None,
                        correction: Correction | None, edges: bool) -> Stepped | None:
        """``step`` of a libcaer_cmp, libcaer or mono stream (the codec's ``packet_step``; ``edges``:
        none, these encodings carry none), restamped as ``restamper.restamp`` restamps it (its time_base
        and stamp moved) without decoding it again, where the restamper's decoder stands where this one
        does (else None: apart)."""
        if correction is not None and (restamper is None or not restamper.follows(codec)):
            return None
        got = codec.packet_step(raw, grid_ns=grid_ns, counts=counts)
        if got is None:
            return None
        (n, _, seq, time_base, at, lo, hi, mid, k0, nbins), t = got
        self._check_seq(seq)
        self._went_on(t[:n])
        out, error = None, ''
        if correction is not None:
            assert restamper is not None
            restamper.followed(codec)
            try:
                out = bytearray(raw)
                moved = _move_time_base(out, correction, encoding=str(self.encoding), time_base=time_base, at=at)
                write_stamp(out, moved, _WHAT)
                if n:  # as ``_restamp``: the first event's corrected time
                    write_stamp(out, correction.apply_one(int(t[0])), _WHAT)
            except MessageError as exc:
                out, error = None, str(exc)
        return Stepped(t[:n], lo, hi, mid, k0, counts[:nbins] if nbins >= 0 else None, out, error,
                       TriggerEdges.empty() if edges else None)

    def _went_on(self, t: npt.NDArray[np.int64]) -> None:
        """A message's times, after the stream's last: times going backwards are counted."""
        if t.size:
            if self._last_t is not None and t[0] < self._last_t:
                self._own.count('time going backwards between messages')
            self._last_t = int(t[-1])

    def _check_seq(self, seq: int) -> None:
        if self._last_seq is not None:
            if seq > self._last_seq + 1:
                self._own.count(SEQ_GAP, seq - self._last_seq - 1)
                self.lost += seq - self._last_seq - 1
            elif seq <= self._last_seq:
                self._own.count('seq not increasing (duplicate, reordered or restarted)')
        self._last_seq = seq

    def _to_ros_time(self, view: PacketView, t: np.ndarray) -> None:
        if view.time_base:
            t += np.int64(view.time_base)
            return
        self._anchor(view.stamp_ns, t)

    def _anchor(self, stamp_ns: int, t: np.ndarray) -> None:
        """Sensor times onto the camera's timeline by the stream's anchor (``evt3_anchor``)."""
        if t.size == 0:
            return
        anchor = evt3_anchor(self.anchor_ns, stamp_ns - int(t[0]))
        self._anchored(anchor)
        t += np.int64(anchor)

    def _anchored(self, anchor: int) -> None:
        """The stream's anchor from here (a change counted: the sensor clock jumped)."""
        if self.anchor_ns is not None and anchor != self.anchor_ns:
            self._own.count('sensor clock jump (re-anchored to header.stamp)')
        self.anchor_ns = anchor


def evt3_anchor(anchor_ns: int | None, first_ns: int) -> int:
    """An evt3 stream's anchor after a message whose header.stamp minus first sensor time is
    ``first_ns``: kept, unless there is none yet or it moved by more than ``REANCHOR_NS``."""
    if anchor_ns is None or abs(first_ns - anchor_ns) > REANCHOR_NS:
        return first_ns
    return anchor_ns


def restamp_event_packet(raw: bytes | bytearray | memoryview, correction: Correction) -> bytearray:
    """A copy of a serialized EventPacket with its times corrected (the table in the module docstring).

    The payload is copied byte for byte. MessageError for an unknown encoding or the big-endian
    flag (what its times mean is unknown), or when a corrected time leaves its field's range.
    """
    out = bytearray(raw)
    view = parse_event_packet(out)
    _check_encoding(view)
    stamp = correction.apply_one(view.stamp_ns)
    if _moves_time_base(view):
        time_base = _move_time_base(out, correction, encoding=view.encoding, time_base=view.time_base,
                                    at=view.time_base_offset)
        if view.encoding != 'evt3':
            # libcaer_driver's header.stamp is the host's arrival time, on the host clock, which drifts
            # from the sensor clock its events ride: moved by the sensor clock's correction it would be
            # on neither timeline. It becomes the message's time_base on the rig's timeline, the time
            # of its events (docs/messages.md)
            stamp = time_base
    write_stamp(out, stamp, _WHAT)
    return out


def _move_time_base(out: bytearray, correction: Correction, *, encoding: str, time_base: int, at: int) -> int:
    """A packet's ``time_base`` (at byte ``at`` of ``out``) moved by ``correction``: the new one.
    MessageError when it leaves uint64."""
    moved = correction.apply_one(time_base)
    if not 0 <= moved < 1 << 64:
        raise MessageError(f'EventPacket ({encoding}): restamped time_base {moved} ns leaves uint64')
    struct.pack_into('<Q', out, at, moved)
    return moved


class EventPacketStreamRestamper:
    """Restamps one stream's EventPackets, in stream order, whose correction may change from message
    to message; ``header.stamp`` follows the one rule of docs/messages.md: the message's first
    event's time on the corrected timeline, as a consumer decodes it.

    Consumers anchor evt3 sensor time once (``header.stamp`` minus the first event's sensor time)
    and re-anchor only on a change of more than ``REANCHOR_NS``. So an evt3 stream is given one
    output anchor A_out, fixed at its first message with an event (the input's anchor A_in, as
    ``EventPacketDecoder`` takes it, moved by the correction there), and every valid time word is
    written as (corrected time - A_out) in us. While the correction stays what it was at the first
    message, that changes nothing and the payload is copied as it is; a later change (the lock
    after forwarding, an updated offset, a skew) reaches the time words. A change of more than
    ``REANCHOR_NS`` (a lock onto a clock seconds away, a jump) moves the output anchor instead,
    which the stamp carries, as consumers re-anchor on it. Each message's stamp is A_out plus its
    first event's time word as written, so a consumer that starts at any message anchors exactly
    at A_out. Other encodings: their payload times are relative to ``time_base``, which moves with
    each message (``restamp_event_packet``); their stamp is the first event's corrected time.

    MessageError, the stream's state left as it was, for a message its decoder refuses.
    """

    def __init__(self) -> None:
        self._decoder = EventPacketDecoder()
        """Other encodings: the first event's time."""
        self._retimer = Evt3Retimer(0.0)
        self._anchors = np.zeros(4, np.int64)
        """evt3: whether A_in is known, A_in, whether A_out is known, A_out (ns): shared with the C path."""

    @property
    def retimer(self) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """Its evt3 state and anchors, which the C calls move on (``EventPacketDecoder.step``)."""
        return self._retimer.state, self._anchors

    @property
    def _in_anchor(self) -> int | None:
        return int(self._anchors[1]) if self._anchors[0] else None

    @_in_anchor.setter
    def _in_anchor(self, value: int) -> None:
        self._anchors[:2] = (1, value)

    @property
    def _out_anchor(self) -> int | None:
        return int(self._anchors[3]) if self._anchors[2] else None

    @_out_anchor.setter
    def _out_anchor(self, value: int) -> None:
        self._anchors[2:] = (1, value)

    def restamp(self, raw: bytes | bytearray | memoryview, correction: Correction) -> bytearray:
        # a well-formed evt3 packet with time_base 0 (what metavision_driver sends): the branch below,
        # step for step, in one C call (_kernels.evt3_packet_restamp); anything else comes down here
        done = _kernels.evt3_packet_restamp(raw, self._retimer.state, self._anchors, correction.skew_ppm * 1e-6,
                                            correction.offset_ns, correction.anchor_ns, False)
        return self._restamp(raw, correction) if done is None else self.written(raw, done)

    def follows(self, codec: TimeBaseStep) -> bool:
        """Whether this restamper's decoder stands where a stream decoder's ``codec`` does, so that a
        message ``codec`` decodes next needs no decoding here (``EventPacketDecoder.step``)."""
        mine = self._decoder._codec
        return isinstance(mine, TimeBaseStep) and mine.stands_with(codec)

    def followed(self, codec: TimeBaseStep) -> None:
        """A message ``codec`` decoded, taken as decoded here too (only the state that decodes the next
        one moves: this decoder's own counts are never read)."""
        mine = self._decoder._codec
        assert isinstance(mine, TimeBaseStep)
        mine.catch_up(codec)

    @staticmethod
    def written(raw: bytes | bytearray | memoryview, done: tuple[int, bytearray | None, bytes | None]) -> bytearray:
        """The message out of what the C restamp gave for ``raw`` ((stamp, copy, retimed):
        ``_kernels.evt3_packet_restamp``). MessageError when its stamp leaves builtin_interfaces/Time."""
        stamp, out, retimed = done
        if retimed is not None:  # time words moved in a packet the C call did not write whole: encoded here
            view = parse_event_packet(raw)
            out = bytearray(encode_event_packet(stamp_ns=0, frame_id=view.frame_id, width=view.width,
                                                height=view.height, seq=view.seq, time_base=view.time_base,
                                                encoding=view.encoding, payload=retimed))
        assert out is not None  # the copy, or the packet around the retimed payload
        write_stamp(out, stamp, _WHAT)
        return out

    def restamp_ros1(self, raw: bytes | bytearray | memoryview, correction: Correction) -> bytearray | None:
        """A ROS 1 EventPacket restamped, as ROS 1 bytes: byte for byte ``event_packet_to_ros1`` of
        ``restamp`` of ``event_packet_from_ros1`` (the Header's seq kept), for a plain evt3 packet
        (time_base 0) in one C call, whose header.stamp sits where CDR's does; None for any other
        message (nothing moved: convert it and call ``restamp``). MessageError as ``restamp``."""
        done = _kernels.evt3_packet_restamp(raw, self._retimer.state, self._anchors, correction.skew_ppm * 1e-6,
                                            correction.offset_ns, correction.anchor_ns, True)
        if done is None:
            return None
        stamp, out, retimed = done
        if retimed is not None:  # time words moved: the packet encoded around them, in CDR, then back
            cdr = event_packet_from_ros1(raw)
            assert cdr is not None  # the kernel took it for what that converts
            view = parse_event_packet(cdr)
            new = bytearray(encode_event_packet(stamp_ns=0, frame_id=view.frame_id, width=view.width,
                                                height=view.height, seq=view.seq, time_base=view.time_base,
                                                encoding=view.encoding, payload=retimed))
            write_stamp(new, stamp, _WHAT)
            back = event_packet_to_ros1(new, seq=int.from_bytes(raw[:4], 'little'))
            assert back is not None  # a well-formed packet, just encoded
            return bytearray(back)
        assert out is not None
        write_stamp(out, stamp, _WHAT)  # header.stamp: at bytes 4-12 in ROS 1 as in CDR
        return out

    def restamp_rows(self, chunk: bytes | memoryview, rows: npt.NDArray[np.int64], start: int, correction: Correction,
                     stamps: npt.NDArray[np.int64], new: list[bytes | bytearray | None], *, ros1: bool = False
                     ) -> int:
        """``restamp`` of each message of ``chunk`` that ``rows`` point to (int64 rows: data offset and
        length, then two more columns), from row ``start`` on, in one C call, for as long as each
        is a plain evt3 packet (CDR; with ``ros1``, ROS 1 bytes, as ``restamp_ros1``): its new
        header.stamp into ``stamps`` where its time words stay (the message is otherwise unchanged),
        else the packet around its retimed words into ``new`` (where its other fields are encoded
        as ``encode_event_packet`` encodes them); the stream's state moved on. Returns the first
        row it leaves, the state as before it, for ``restamp`` (``len(rows)``: none left)."""
        return _kernels.evt3_packets_restamp(chunk, rows, start, self._retimer.state, self._anchors,
                                             correction.skew_ppm * 1e-6, correction.offset_ns, correction.anchor_ns,
                                             stamps, new, ros1)

    def _restamp(self, raw: bytes | bytearray | memoryview, correction: Correction) -> bytearray:
        view = parse_event_packet(raw)
        _check_encoding(view)
        if view.encoding != 'evt3' or view.time_base:
            _, events, edges = self._decoder.decode_edges(raw)
            out = restamp_event_packet(raw, correction)
            times = edges.t if view.encoding == 'trigger' else events.t  # a trigger stream's events: its edges
            if times.size:
                write_stamp(out, correction.apply_one(int(times[0])), _WHAT)
            return out
        # the first event's time (the decoders' anchor), and the first that a consumer starting at this
        # message decodes (after a TIME_HIGH and a TIME_LOW of the message's own): sensor us, unwrapped
        first, joining = self._retimer.first_events(view.events, width=view.width, height=view.height)
        if first is not None:
            self._in_anchor = evt3_anchor(self._in_anchor, view.stamp_ns - first * 1000)
        in_anchor = self._in_anchor
        if in_anchor is None:  # no event yet: nothing anchored, nothing moves but the stamp
            self._retimer.retime_to(view.events, in_anchor_ns=0, offset_ns=0, skew_ppm=0.0, anchor_ns=0,
                                    out_anchor_ns=0)
            out = bytearray(raw)
            write_stamp(out, correction.apply_one(view.stamp_ns), _WHAT)
            return out
        if first is not None:
            t0 = first * 1000 + in_anchor
            moved = correction.apply_one(t0) - t0
            if self._out_anchor is None or abs(in_anchor + moved - self._out_anchor) > REANCHOR_NS:
                self._out_anchor = in_anchor + moved
        out_anchor = self._out_anchor
        assert out_anchor is not None  # set with the anchor's first event
        at = joining if joining is not None else first
        if at is None:  # no event: its first time word, if any
            at = self._retimer.first_time(view.events)
        payload = self._retimer.retime_to(view.events, in_anchor_ns=in_anchor, offset_ns=correction.offset_ns,
                                          skew_ppm=correction.skew_ppm, anchor_ns=correction.anchor_ns,
                                          out_anchor_ns=out_anchor)
        if payload is None:
            out = bytearray(raw)
        else:
            out = bytearray(encode_event_packet(stamp_ns=0, frame_id=view.frame_id, width=view.width,
                                                height=view.height, seq=view.seq, time_base=view.time_base,
                                                encoding=view.encoding, payload=payload))
        if at is None:
            stamp = correction.apply_one(view.stamp_ns)
        else:  # that event's time word as written (the retimer's rounding): the consumer's anchor is A_out
            stamp = out_anchor + 1000 * ((correction.apply_one(at * 1000 + in_anchor) - out_anchor + 500) // 1000)
        write_stamp(out, stamp, _WHAT)
        return out


EventPacketRestamper = EventPacketStreamRestamper
"""A bag's stream, with one correction throughout, is restamped as a live one."""


def encode_event_packet(*, stamp_ns: int, frame_id: str, width: int, height: int, seq: int, time_base: int,
                        encoding: str, payload: bytes) -> bytes:
    """A serialized EventPacket (little endian, is_bigendian false) from its fields."""
    def string(buf: bytearray, text: str) -> None:
        data = text.encode() + b'\x00'
        buf += b'\x00' * (-(len(buf) - 4) % 4)
        buf += struct.pack('<I', len(data)) + data

    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    out = bytearray(struct.pack('<4siI', b'\x00\x01\x00\x00', sec, nsec))
    string(out, frame_id)
    out += b'\x00' * (-(len(out) - 4) % 4)
    out += struct.pack('<II', height, width)
    out += b'\x00' * (-(len(out) - 4) % 8)
    out += struct.pack('<QQ', seq, time_base)
    string(out, encoding)
    out += b'\x00'  # is_bigendian
    out += b'\x00' * (-(len(out) - 4) % 4)
    out += struct.pack('<I', len(payload)) + payload
    return bytes(out)



# -- ROS 1: the same message, packed (no alignment), a Header with seq, strings without their NUL --

_ROS1_HEIGHT_TO_TIME_BASE = 24
"""Bytes of height, width (uint32), seq and time_base (uint64): packed in ROS 1, and in CDR too once
height is aligned (4) and seq (8)."""


def _pad(out: bytearray, size: int) -> None:
    out += bytes(-(len(out) - 4) % size)


def event_packet_from_ros1(raw: bytes | bytearray | memoryview) -> bytes | None:
    """The CDR bytes of a ROS 1 EventPacket (every field as it was; the Header's seq dropped, as ROS 2
    has none), byte for byte what rosbags' converter writes, in a few copies instead of its
    generated code; None when ``raw`` is not exactly such a message (lengths that do not add up, an
    is_bigendian byte other than 0 or 1), for the general converter to judge."""
    n = len(raw)
    if n < 16:
        return None
    (frame_len,) = struct.unpack_from('<I', raw, 12)
    pos = 16 + frame_len
    if pos + _ROS1_HEIGHT_TO_TIME_BASE + 4 > n:
        return None
    fixed = pos
    (encoding_len,) = struct.unpack_from('<I', raw, pos + _ROS1_HEIGHT_TO_TIME_BASE)
    encoding = pos + _ROS1_HEIGHT_TO_TIME_BASE + 4
    pos = encoding + encoding_len
    if pos + 5 > n or raw[pos] > 1:
        return None
    (n_bytes,) = struct.unpack_from('<I', raw, pos + 1)
    if pos + 5 + n_bytes != n:
        return None
    out = bytearray(b'\x00\x01\x00\x00')
    out += raw[4:12]
    out += struct.pack('<I', frame_len + 1)
    out += raw[16:16 + frame_len]
    out += b'\x00'
    _pad(out, 4)
    out += raw[fixed:fixed + 8]
    _pad(out, 8)
    out += raw[fixed + 8:fixed + _ROS1_HEIGHT_TO_TIME_BASE]
    out += struct.pack('<I', encoding_len + 1)
    out += raw[encoding:encoding + encoding_len]
    out += b'\x00'
    out += raw[pos:pos + 1]
    _pad(out, 4)
    out += raw[pos + 1:]
    return bytes(out)


def event_packet_to_ros1(cdr: bytes | bytearray | memoryview, *, seq: int = 0) -> bytes | None:
    """The ROS 1 bytes of a CDR EventPacket, with header ``seq``: the inverse of
    ``event_packet_from_ros1``, byte for byte rosbags' result; None when ``cdr`` is not exactly a
    well-formed EventPacket (bytes after its events, an is_bigendian byte other than 0 or 1), for
    the general converter to judge."""
    try:
        view = parse_event_packet(cdr)
    except MessageError:
        return None
    (frame_len,) = struct.unpack_from('<I', cdr, FRAME_ID_OFFSET)
    encoding = view.time_base_offset + 12
    (encoding_len,) = struct.unpack_from('<I', cdr, encoding - 4)
    flag = encoding + encoding_len
    events = align(flag + 1, 4) + 4
    if cdr[flag] > 1 or events + view.events.size != len(cdr):
        return None
    out = bytearray(struct.pack('<I', seq))
    out += cdr[4:12]
    out += struct.pack('<I', frame_len - 1)
    out += cdr[16:16 + frame_len - 1]
    out += struct.pack('<II', view.height, view.width)
    out += cdr[view.time_base_offset - 8:view.time_base_offset + 8]  # seq, time_base
    out += struct.pack('<I', encoding_len - 1)
    out += cdr[encoding:encoding + encoding_len - 1]
    out += cdr[flag:flag + 1]
    out += cdr[events - 4:]
    return bytes(out)
