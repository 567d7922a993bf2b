"""Prophesee EVT 3.0 payloads (EventPacket encoding ``evt3``), decoded statefully.

Little-endian 16-bit words, type in the top 4 bits:

    0x0 ADDR_Y       y = bits 0-10
    0x2 ADDR_X       x = bits 0-10, polarity bit 11: one event at the current y and time
    0x3 VECT_BASE_X  base x = bits 0-10, polarity bit 11
    0x4 VECT_12      12-bit mask: an event at base_x + i per set bit i; then base_x += 12
    0x5 VECT_8       8-bit mask, likewise; base_x += 8
    0x6 TIME_LOW     time bits 0-11 (microseconds)
    0x8 TIME_HIGH    time bits 12-23
    0xA EXT_TRIGGER  a trigger edge at the current time: value bit 0 (1 rising), channel bits 8-11
    0xE OTHERS, 0x7 / 0xF CONTINUED, 0x9 (padding of some cameras): no event

Time is 24 bits of microseconds, wrapping every 16.777216 s. A TIME_HIGH smaller than the one
before by more than 10 counts as a wrap (smaller backward steps happen without one and are
counted as anomalies); wraps are counted in the decoder state, so times stay monotonic across
messages. Events before the stream's first TIME_HIGH-then-TIME_LOW pair have no valid time and
are not emitted, as event_camera_codecs does; events outside the sensor geometry are counted. The
whole state (time high and low, wrap count, y, base x, polarity) carries from one message to the
next. The word loop is C (``msg_adapters/_kernels.c``).

Trigger edges come out of the same walk when asked for (``decode_edges``), with the time the
events beside them have; an EXT_TRIGGER word before the stream's first valid time is counted, not
emitted (the events before it are not emitted either). ``decode`` passes EXT_TRIGGER words over.

Times are *sensor* time: metavision_driver sets time_base = 0 and the payload alone holds time.
``EventPacketDecoder`` anchors them to ROS time (see ``event_packet.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from msg_adapters import _kernels
from msg_adapters.edges import EdgeScratch, TriggerEdges
from msg_adapters.events import Events, WordLoopDecoder, byte_view, whole_units


class Evt3Decoder(WordLoopDecoder):
    """Stateful decoder of one stream's evt3 payloads."""

    counter_names = ('unknown word type', 'small backward time step', 'event outside the sensor geometry',
                     "trigger edge before the stream's first time (not emitted)")
    per_word = 12

    def __init__(self, *, width: int, height: int) -> None:
        # TIME_HIGH, TIME_LOW (-1: none yet), wraps, y, base x, polarity, valid
        super().__init__(width=width, height=height, state=[-1, -1, 0, 0, 0, 0, 0])
        self._edge_scratch = EdgeScratch()

    def decode(self, payload: np.ndarray | bytes | memoryview, *, xyp: bool = False) -> Events:
        """Decode one message's payload; the state moves on to its end."""
        return self._run(_kernels.evt3_decode, payload, xyp)

    def decode_edges(self, payload: np.ndarray | bytes | memoryview, *, xyp: bool = False
                     ) -> tuple[Events, TriggerEdges]:
        """``decode``, and the payload's trigger edges (sensor times in ns, as the events'), in one walk."""
        buf = whole_units(byte_view(payload), 2, self.anomalies, 'odd byte count')
        sc, es = self._scratch, self._edge_scratch
        cap, edge_cap = sc.ensure(buf.size // 2), es.ensure(buf.size // 2)
        x, y, p = (sc.x, sc.y, sc.p) if xyp else (None, None, None)
        n, n_edges, odd = _kernels.evt3_decode_edges(buf, self._state, self._counters, self.width, self.height, cap,
                                                     sc.t, x, y, p, edge_cap, es.t, es.value, es.channel)
        if odd:
            self.anomalies.merge(self._counters, self.counter_names)
        return sc.events(n, xyp=xyp), es.edges(n_edges)

    def decode_packet(self, raw: bytes | bytearray | memoryview, *, ros1: bool = False
                      ) -> tuple[Events, int, int] | None:
        """A whole serialized EventPacket in one call, when it is plain (encoding evt3, little-endian,
        time_base 0, well formed, this decoder's geometry, whole words): its events' sensor times,
        header.stamp and seq, the state moved on as ``decode`` moves it. None for any other
        message, nothing moved. ``ros1``: ``raw`` is a ROS 1 message, taken where its conversion
        (``event_packet_from_ros1``) would be plain."""
        sc = self._scratch
        cap = sc.ensure(len(raw) // 2)
        got = _kernels.evt3_packet_decode(raw, self._state, self._counters, self.width, self.height, cap, sc.t,
                                          None, None, None, ros1)
        if got is None:
            return None
        n, odd, stamp_ns, seq = got
        if odd:
            self.anomalies.merge(self._counters, self.counter_names)
        return sc.events(n, xyp=False), stamp_ns, seq

    def decode_packet_edges(self, raw: bytes | bytearray | memoryview, *, ros1: bool = False
                            ) -> tuple[Events, TriggerEdges, int, int] | None:
        """``decode_packet``, and the payload's trigger edges (sensor times in ns), in the same C call:
        (events, edges, header.stamp, seq), or None, nothing moved."""
        sc, es = self._scratch, self._edge_scratch
        cap, edge_cap = sc.ensure(len(raw) // 2), es.ensure(len(raw) // 2)
        got = _kernels.evt3_packet_decode_edges(raw, self._state, self._counters, self.width, self.height, cap, sc.t,
                                                None, None, None, edge_cap, es.t, es.value, es.channel, ros1)
        if got is None:
            return None
        n, n_edges, odd, stamp_ns, seq = got
        if odd:
            self.anomalies.merge(self._counters, self.counter_names)
        return sc.events(n, xyp=False), es.edges(n_edges), stamp_ns, seq

    def packet_step(self, raw: bytes | bytearray | memoryview, *, anchor: int | None, grid_ns: int,
                    counts: np.ndarray, retimer: tuple[np.ndarray, np.ndarray] | None,
                    correction: tuple[float, int, int], edges: bool = False
                    ) -> tuple[tuple[Any, ...], np.ndarray, TriggerEdges | None] | None:
        """``decode_packet`` of a plain packet, onto the camera's timeline by the stream's ``anchor``,
        its events counted on the grid of ``grid_ns`` into ``counts`` and, with a stream restamper's
        ``retimer`` (its state and anchors), restamped by ``correction`` (k, offset, anchor), in one C
        call (``_kernels.evt3_packet_step``: what it returns, the scratch its times are in and, with
        ``edges``, its trigger edges as ``decode_packet_edges`` gives them). None for any other
        message, nothing moved."""
        sc, es = self._scratch, self._edge_scratch
        cap = sc.ensure(len(raw) // 2)
        edge_cap = es.ensure(len(raw) // 2) if edges else 0
        state, anchors = retimer if retimer is not None else (_NO_RETIMER, _NO_ANCHORS)
        got = _kernels.evt3_packet_step(raw, self._state, self._counters, self.width, self.height, cap, sc.t,
                                        anchor or 0, anchor is not None, grid_ns,
                                        counts, retimer is not None, state, anchors, *correction, edge_cap,
                                        (es.t, es.value, es.channel) if edges else None)
        if got is None:
            return None
        if got[1]:
            self.anomalies.merge(self._counters, self.counter_names)
        return got, sc.t, es.edges(got[-1]) if edges else None


_NO_RETIMER = np.zeros(6, np.int64)
"""``packet_step`` without a restamp: state buffers it never writes."""
_NO_ANCHORS = np.zeros(4, np.int64)


def encode_evt3(t_us: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, *,
                edges: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> bytes:
    """evt3 words for time-sorted events (sensor microseconds, any size: the low 24 bits are sent),
    and with ``edges`` (times in the same microseconds, sorted, values 0/1, channels 0-15) trigger
    edges as EXT_TRIGGER words among them in time order (at equal times, after the events).

    Every payload starts with TIME_HIGH, TIME_LOW and ADDR_Y words, so it decodes on its own as well
    as in a stream; after that a time or y word is written only when its value changes, then one
    ADDR_X per event and one EXT_TRIGGER per edge. Used by the simulator and the tests; drivers
    write evt3 themselves.
    """
    t_us = np.asarray(t_us, np.int64)
    n_events = t_us.size
    is_edge = np.zeros(n_events, bool)
    last = (0x2 << 12) | (np.asarray(x, np.int64) & 0x7FF) | ((np.asarray(p, np.int64) & 1) << 11)
    y = np.asarray(y, np.int64) & 0x7FF
    if edges is not None and np.asarray(edges[0]).size:
        edge_t, value, channel = (np.asarray(a, np.int64) for a in edges)
        order = np.argsort(np.concatenate([t_us, edge_t]), kind='stable')
        t_us = np.concatenate([t_us, edge_t])[order]
        is_edge = np.concatenate([is_edge, np.ones(edge_t.size, bool)])[order]
        last = np.concatenate([last, (0xA << 12) | ((channel & 0xF) << 8) | (value & 1)])[order]
        y = np.concatenate([y, np.zeros(edge_t.size, np.int64)])[order]
    t_us = t_us & 0xFFFFFF
    n = t_us.size
    if n == 0:
        return b''
    high = (t_us >> 12) & 0xFFF
    low = t_us & 0xFFF
    new_high = np.ones(n, bool)
    new_high[1:] = high[1:] != high[:-1]
    new_low = np.ones(n, bool)
    new_low[1:] = low[1:] != low[:-1]
    new_y = np.zeros(n, bool)  # an event's y word, where it differs from the event before's
    at_event = np.flatnonzero(~is_edge)
    if at_event.size:
        event_y = y[at_event]
        new_y[at_event] = np.concatenate([[True], event_y[1:] != event_y[:-1]])
    per_item = new_high.astype(np.int64) + new_low + new_y + 1
    end = np.cumsum(per_item)
    words = np.empty(int(end[-1]), np.uint16)
    pos = end - 1
    words[pos] = last.astype(np.uint16)
    pos_y = pos - new_y
    words[pos_y[new_y]] = (y[new_y]).astype(np.uint16)
    pos_low = pos_y - new_low
    words[pos_low[new_low]] = ((0x6 << 12) | low[new_low]).astype(np.uint16)
    pos_high = pos_low - new_high
    words[pos_high[new_high]] = ((0x8 << 12) | high[new_high]).astype(np.uint16)
    return words.astype('<u2').tobytes()


class Evt3Retimer:
    """Rewrites one stream's evt3 time words so that sensor time u reads u + round(k (u - u0)).

    k is ``skew_ppm`` * 1e-6 and u0 the stream's first valid time: a clock skew carried into the
    payload itself, which decoders that anchor evt3 sensor time once (ours, event_camera_codecs)
    then see. Each valid TIME_HIGH or TIME_LOW word becomes a TIME_LOW of the corrected time,
    preceded by a TIME_HIGH where the corrected high part changes, so every event word keeps its
    place and takes the corrected time of the state it had; each payload's first time word writes
    its high part. A TIME_HIGH that no event word follows only moves the high part on: it is
    written as a TIME_HIGH alone, and only when the corrected high part changes. Words before the
    stream's first valid time are copied. Like the decoder, the state (high, low, wraps) carries
    from one message to the next, so messages must come in stream order. The word walk is C
    (``_kernels.evt3_retime``); ``evsync_testing.reference.ReferenceRetimer`` is the same walk
    in numpy, the tests' oracle.
    """

    def __init__(self, skew_ppm: float) -> None:
        self.k = skew_ppm * 1e-6
        # TIME_HIGH, TIME_LOW (-1: none yet), wraps, unwrapped time at the last TIME_LOW (-1: none),
        # the stream's first valid time u0, whether u0 is known
        self._state = np.array([-1, -1, 0, -1, 0, 0], np.int64)

    @property
    def state(self) -> np.ndarray:
        """The walk's state (int64, in place): what a whole-message kernel carries on."""
        return self._state

    @property
    def u0(self) -> int | None:
        """The stream's first valid time (us), None before it."""
        return int(self._state[4]) if self._state[5] else None

    def retime(self, payload: np.ndarray | bytes | memoryview) -> bytes:
        """The payload with its time words rewritten by the skew; a payload no time of which moves
        comes back unchanged (the state still moves on)."""
        out = _kernels.evt3_retime(_buffer(payload), self._state, 0, self.k, 0, 0, 0, 0)
        return bytes(payload) if out is None else out

    def first_time(self, payload: np.ndarray | bytes | memoryview) -> int | None:
        """The payload's first valid time u (us, unwrapped from the state), None if it has none; the
        state does not move."""
        u = _kernels.evt3_first_time(_buffer(payload), self._state)
        return None if u < 0 else int(u)

    def first_events(self, payload: np.ndarray | bytes | memoryview, *, width: int, height: int
                     ) -> tuple[int | None, int | None]:
        """(the payload's first event's time u, the first event after a TIME_HIGH and a TIME_LOW of
        the payload's own: where a decoder starting at this payload begins), us unwrapped from the
        state, None where there is none; the state does not move."""
        first, joining = _kernels.evt3_first_events(_buffer(payload), self._state, width, height)
        return (None if first < 0 else int(first)), (None if joining < 0 else int(joining))

    def retime_to(self, payload: np.ndarray | bytes | memoryview, *, in_anchor_ns: int, offset_ns: int,
                  skew_ppm: float, anchor_ns: int, out_anchor_ns: int) -> bytes | None:
        """The payload with each valid time u rewritten to (c(u 1000 + in_anchor) - out_anchor) in us,
        rounded, c(t) = t + offset + round(skew (t - anchor)): a live stream's correction c, its
        input times anchored at ``in_anchor_ns`` and its output at ``out_anchor_ns``. None when no
        time moves (the payload stands as it is); the state moves on either way."""
        return _kernels.evt3_retime(_buffer(payload), self._state, 1, skew_ppm * 1e-6, in_anchor_ns, offset_ns,
                                    anchor_ns, out_anchor_ns)


def _buffer(payload: np.ndarray | bytes | memoryview) -> bytes | memoryview:
    return payload if isinstance(payload, (bytes, memoryview)) else np.ascontiguousarray(payload).data


