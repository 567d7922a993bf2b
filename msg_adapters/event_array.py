"""dvs_msgs/EventArray and prophesee_event_msgs/EventArray straight from CDR bytes.

Both types have the same fields, so one module serves both:

    std_msgs/Header header, uint32 height, uint32 width,
    Event[] events   with Event = uint16 x, uint16 y, builtin_interfaces/Time ts, bool polarity

Every event carries an absolute time (int32 sec, uint32 nanosec) on the camera's ROS timeline.

CDR (XCDR1, little endian) aligns each field to its size counted from the end of the 4-byte
encapsulation header, so the element layout depends on where each element starts. With the
sequence's first element at byte ``p`` (``p - 4`` a multiple of 4, since it follows the uint32
length), element ``k`` has:

    x        at p          (k = 0)   and  p + 16k - 2  (k >= 1)
    y        at p + 2      (k = 0)   and  p + 16k      (k >= 1)
    ts.sec   at p + 16k + 4
    ts.nsec  at p + 16k + 8
    polarity at p + 16k + 12

and the last element ends at p + 16n - 3. The times, and the polarity, are thus fixed-stride
(16-byte) arrays, which numpy reads and writes in place.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from msg_adapters import _kernels
from msg_adapters.cdr import (
    FRAME_ID_OFFSET,
    INT32_MAX,
    INT32_MIN,
    NS,
    align,
    check_encapsulation,
    read_stamp,
    read_string,
    write_stamp,
)
from msg_adapters.edges import TriggerEdges
from msg_adapters.errors import MessageError
from msg_adapters.events import Anomalies, Events, Stepped
from msg_adapters.protocols import Correction


@dataclass(frozen=True)
class ArrayView:
    """Where an EventArray's fields sit in its serialized bytes."""

    stamp_ns: int
    frame_id: str
    height: int
    width: int
    count: int
    first: int
    """Byte offset of the first event element."""


def parse_event_array(raw: bytes | bytearray | memoryview, *, what: str = 'EventArray') -> ArrayView:
    """Read an EventArray's CDR bytes; MessageError when they do not hold one."""
    check_encapsulation(raw, what)
    frame_id, pos = read_string(raw, FRAME_ID_OFFSET, 'header.frame_id', what)
    pos = align(pos, 4)
    if pos + 12 > len(raw):
        raise MessageError(f'{what} truncated before height/width/events')
    height, width, count = struct.unpack_from('<III', raw, pos)
    first = pos + 12
    end = first + 16 * count - 3 if count else first
    if end > len(raw):
        raise MessageError(f'{what} truncated: {count} events declared need {end} bytes, {len(raw)} present')
    return ArrayView(read_stamp(raw), frame_id, height, width, count, first)


def _field(buf: bytes | bytearray | memoryview, view: ArrayView, offset: int, dtype: str) -> np.ndarray:
    """The fixed-stride field at ``first + 16k + offset`` of every element, as a numpy view."""
    if view.count == 0:
        return np.empty(0, dtype)
    return np.ndarray((view.count,), dtype=dtype, buffer=buf, offset=view.first + offset, strides=(16,))


def _xy(buf: bytes | bytearray | memoryview, view: ArrayView) -> tuple[np.ndarray, np.ndarray]:
    x = np.empty(view.count, np.uint16)
    y = np.empty(view.count, np.uint16)
    if view.count:
        x[0], y[0] = struct.unpack_from('<HH', buf, view.first)
    rest = view.count - 1
    if rest > 0:
        x[1:] = np.ndarray((rest,), '<u2', buffer=buf, offset=view.first + 14, strides=(16,))
        y[1:] = np.ndarray((rest,), '<u2', buffer=buf, offset=view.first + 16, strides=(16,))
    return x, y


class EventArrayDecoder:
    """Decoder of one stream's dvs or prophesee EventArray messages (no state but the counts)."""

    def __init__(self, *, what: str = 'EventArray') -> None:
        self.what = what
        self.anomalies = Anomalies()

    def decode(self, raw: bytes | bytearray | memoryview, *, xyp: bool = False) -> tuple[ArrayView, Events]:
        """One message's fields and events (``ts`` as int64 ns; x, y, polarity too with ``xyp``);
        MessageError when the bytes do not hold an EventArray."""
        view = parse_event_array(raw, what=self.what)
        sec = _field(raw, view, 4, '<i4')
        nsec = _field(raw, view, 8, '<u4')
        t = sec.astype(np.int64)
        t *= NS
        t += nsec
        self._counted(int(np.count_nonzero(nsec >= NS)), int(np.count_nonzero(t[1:] < t[:-1])))
        if not xyp:
            return view, Events(t)
        x, y = _xy(raw, view)
        p = (_field(raw, view, 12, 'u1') != 0).astype(np.uint8)
        return view, Events(t, x, y, p)

    def decode_edges(self, raw: bytes | bytearray | memoryview, *, xyp: bool = False
                     ) -> tuple[ArrayView, Events, TriggerEdges]:
        """``decode``, and no trigger edges (an EventArray carries none): the same call for every
        event type (``EventPacketDecoder.decode_edges``)."""
        view, events = self.decode(raw, xyp=xyp)
        return view, events, TriggerEdges.empty()

    def decode_times_edges(self, raw: bytes | bytearray | memoryview) -> tuple[npt.NDArray[np.int64], TriggerEdges]:
        """``decode_times``, and no trigger edges."""
        return self.decode_times(raw), TriggerEdges.empty()

    def step(self, raw: bytes | bytearray | memoryview, *, grid_ns: int, counts: npt.NDArray[np.int32],
             restamper: object, correction: Correction | None, edges: bool = False) -> Stepped | None:
        """A live stream's next message in one C call (``_kernels.event_array_step``): decoded as
        ``decode_times`` decodes it, counted on the grid of ``grid_ns`` (into ``counts``) and, given a
        ``correction``, restamped as ``restamp_event_array_stamped`` restamps it (``restamper``: an
        EventPacket stream's, unused here; ``edges``: none, an EventArray carries none). None, nothing
        counted, for bytes that are no EventArray."""
        c = correction
        got = _kernels.event_array_step(raw, grid_ns, counts, c is not None, 0 if c is None else c.offset_ns,
                                        0.0 if c is None else c.skew_ppm * 1e-6, 0 if c is None else c.anchor_ns,
                                        c is None or c.is_identity)
        if got is None:
            return None
        times, bad_nsec, backwards, lo, hi, mid, k0, nbins, out = got
        self._counted(bad_nsec, backwards)
        error = ''
        if c is not None and out is None:  # a time leaves its field, or the like: numpy says what
            try:
                out = restamp_event_array_stamped(raw, c, what=self.what)
            except MessageError as exc:
                error = str(exc)
        return Stepped(np.frombuffer(times, np.int64), lo, hi, mid, k0, counts[:nbins] if nbins >= 0 else None, out,
                       error, TriggerEdges.empty() if edges else None)

    def _counted(self, bad_nsec: int, backwards: int) -> None:
        self.anomalies.count('ts.nanosec of 1e9 or more', bad_nsec)
        self.anomalies.count('time going backwards within a message', backwards)

    def decode_times(self, raw: bytes | bytearray | memoryview) -> npt.NDArray[np.int64]:
        """``decode(raw)[1].t``, in one C call where the message is well formed."""
        times = self._times(raw, ros1=False)
        return self.decode(raw)[1].t if times is None else times

    def decode_ros1_times(self, raw: bytes | bytearray | memoryview) -> npt.NDArray[np.int64] | None:
        """``decode_times`` of a ROS 1 EventArray's CDR (``event_array_from_ros1``), from its ROS 1
        bytes; None, nothing counted, where it is not one (to be converted, which says why)."""
        return self._times(raw, ros1=True)

    def _times(self, raw: bytes | bytearray | memoryview, *, ros1: bool) -> npt.NDArray[np.int64] | None:
        got = _kernels.event_array_times(raw, ros1)
        if got is None:
            return None
        times, bad_nsec, backwards = got
        self._counted(bad_nsec, backwards)
        return np.frombuffer(times, np.int64)


def restamp_event_array(raw: bytes | bytearray | memoryview, correction: Correction, *,
                        what: str = 'EventArray') -> bytearray:
    """A copy of a serialized EventArray with header.stamp and every event's ts corrected.

    Nothing else changes: not x, y, polarity, frame_id, nor any padding byte. MessageError when a
    corrected time leaves the range builtin_interfaces/Time can hold.
    """
    return _restamped(raw, correction, what)[0]


def restamp_event_array_stamped(raw: bytes | bytearray | memoryview, correction: Correction, *,
                                what: str = 'EventArray') -> bytearray:
    """``restamp_event_array``, then header.stamp the first event's corrected ``ts`` (a message without
    events keeps its corrected stamp): the stamp rule of a restamped stream (``registry.Restamper``),
    in one pass over the bytes (in C, ``_kernels.event_array_restamp``, for a well-formed message whose
    times all stay in range; anything else in numpy, which says what is wrong)."""
    done = _kernels.event_array_restamp(raw, correction.offset_ns, correction.skew_ppm * 1e-6, correction.anchor_ns,
                                        correction.is_identity, False)
    if done is not None:
        return done
    out, first = _restamped(raw, correction, what)
    if first is not None:
        write_stamp(out, first, what)
    return out


def restamp_event_arrays_stamped(chunk: bytes | memoryview, rows: npt.NDArray[np.int64], start: int,
                                 correction: Correction, new: list[bytes | bytearray | None], *,
                                 ros1: bool = False) -> int:
    """``restamp_event_array_stamped`` (with ``ros1``, ``restamp_event_array_ros1``) of each message of
    ``chunk`` that ``rows`` point to (int64 rows: data offset and length, then two more columns),
    from row ``start`` on, its copy into ``new``, in one C call, for as long as the C path takes
    each. Returns the first row it declines, for the message's own path (``len(rows)``: none)."""
    return _kernels.event_arrays_restamp(chunk, rows, start, correction.offset_ns, correction.skew_ppm * 1e-6,
                                         correction.anchor_ns, correction.is_identity, new, ros1)


def _restamped(raw: bytes | bytearray | memoryview, correction: Correction, what: str) -> tuple[bytearray, int | None]:
    """(the restamped copy, its first event's ``ts`` as written: int ns, None without events)."""
    out = bytearray(raw)
    view = parse_event_array(out, what=what)
    write_stamp(out, correction.apply_one(view.stamp_ns), what)
    if view.count == 0:
        return out, None
    sec = _field(out, view, 4, '<i4')
    nsec = _field(out, view, 8, '<u4')
    if not correction.is_identity:
        t = sec.astype(np.int64)
        t *= NS
        t += nsec
        t = correction.apply(t) if correction.skew_ppm else np.add(t, correction.offset_ns, out=t)
        new_sec, new_nsec = np.divmod(t, NS)
        if new_sec.min() < INT32_MIN or new_sec.max() > INT32_MAX:
            raise MessageError(f'{what}: a restamped event time leaves the int32 seconds of builtin_interfaces/Time')
        sec[:] = new_sec
        nsec[:] = new_nsec
    return out, int(sec[0]) * NS + int(nsec[0])


def restamp_event_array_ros1(raw: bytes | bytearray | memoryview, correction: Correction) -> bytearray | None:
    """A ROS 1 EventArray restamped as ``restamp_event_array_stamped`` restamps its CDR, as ROS 1 bytes:
    byte for byte ``event_array_to_ros1`` of that of ``event_array_from_ros1`` (the Header's seq kept),
    in one C call; None when the message is not such (or a time leaves its field): convert it and
    restamp the CDR, which says what is wrong."""
    return _kernels.event_array_restamp(raw, correction.offset_ns, correction.skew_ppm * 1e-6, correction.anchor_ns,
                                        correction.is_identity, True)


def encode_event_array(*, stamp_ns: int, frame_id: str, width: int, height: int, t: np.ndarray,
                       x: np.ndarray, y: np.ndarray, p: np.ndarray) -> bytes:
    """A serialized EventArray (dvs or prophesee: same bytes) from numpy columns, in the layout above."""
    frame = frame_id.encode() + b'\x00'
    head = struct.pack('<4siII', b'\x00\x01\x00\x00', *divmod(int(stamp_ns), NS), len(frame)) + frame
    head += b'\x00' * (-(len(head) - 4) % 4)
    n = int(np.asarray(t).size)
    head += struct.pack('<III', height, width, n)
    first = len(head)
    out = bytearray(first + (16 * n - 3 if n else 0))
    out[:first] = head
    if n:
        view = ArrayView(int(stamp_ns), frame_id, height, width, n, first)
        sec, nsec = np.divmod(np.asarray(t, np.int64), NS)
        if sec.min() < INT32_MIN or sec.max() > INT32_MAX:
            raise MessageError('EventArray: an event time is outside what builtin_interfaces/Time holds')
        _field(out, view, 4, '<i4')[:] = sec
        _field(out, view, 8, '<u4')[:] = nsec
        _field(out, view, 12, 'u1')[:] = np.asarray(p) != 0
        struct.pack_into('<HH', out, first, int(x[0]), int(y[0]))
        if n > 1:
            np.ndarray((n - 1,), '<u2', buffer=out, offset=first + 14, strides=(16,))[:] = np.asarray(x)[1:]
            np.ndarray((n - 1,), '<u2', buffer=out, offset=first + 16, strides=(16,))[:] = np.asarray(y)[1:]
    return bytes(out)


# -- ROS 1: the same message, packed (no alignment), a Header with seq, strings without their NUL --

_ROS1_EVENT = np.dtype([('x', '<u2'), ('y', '<u2'), ('sec', '<u4'), ('nsec', '<u4'), ('p', 'u1')])
"""One event of a ROS 1 EventArray: 13 bytes, packed."""


def event_array_from_ros1(raw: bytes | bytearray | memoryview, *, what: str = 'EventArray') -> bytes:
    """The CDR bytes of a ROS 1 EventArray (every field as it was; the Header's seq dropped, as ROS 2
    has none), byte for byte what rosbags' converter writes, without its Python step per event.
    MessageError when ``raw`` is not such a message."""
    if len(raw) < 28:
        raise MessageError(f'{what} (ROS 1) truncated: {len(raw)} bytes')
    _, sec, nsec, flen = struct.unpack_from('<IIII', raw, 0)
    pos = 16 + flen
    if pos + 12 > len(raw):
        raise MessageError(f'{what} (ROS 1) truncated before height/width/events')
    height, width, n = struct.unpack_from('<III', raw, pos)
    if pos + 12 + 13 * n != len(raw):
        raise MessageError(f'{what} (ROS 1): {n} events declared, {len(raw) - pos - 12} bytes of them')
    ev = np.frombuffer(raw, _ROS1_EVENT, count=n, offset=pos + 12)
    head = b'\x00\x01\x00\x00' + struct.pack('<III', sec, nsec, flen + 1) + bytes(raw[16:pos]) + b'\x00'
    head += b'\x00' * (-(len(head) - 4) % 4)
    head += struct.pack('<III', height, width, n)
    first = len(head)
    out = bytearray(first + (16 * n - 3 if n else 0))
    out[:first] = head
    if n:
        view = ArrayView(0, '', height, width, n, first)
        _field(out, view, 4, '<u4')[:] = ev['sec']
        _field(out, view, 8, '<u4')[:] = ev['nsec']
        _field(out, view, 12, 'u1')[:] = ev['p']
        struct.pack_into('<HH', out, first, int(ev['x'][0]), int(ev['y'][0]))
        if n > 1:
            np.ndarray((n - 1,), '<u2', buffer=out, offset=first + 14, strides=(16,))[:] = ev['x'][1:]
            np.ndarray((n - 1,), '<u2', buffer=out, offset=first + 16, strides=(16,))[:] = ev['y'][1:]
    return bytes(out)


def event_array_to_ros1(raw: bytes | bytearray | memoryview, *, seq: int = 0, what: str = 'EventArray') -> bytes:
    """The ROS 1 bytes of a CDR EventArray, with header ``seq``: the inverse of ``event_array_from_ros1``."""
    view = parse_event_array(raw, what=what)
    (flen,) = struct.unpack_from('<I', raw, FRAME_ID_OFFSET)
    frame = bytes(raw[FRAME_ID_OFFSET + 4:FRAME_ID_OFFSET + 4 + flen - 1])
    ev = np.empty(view.count, _ROS1_EVENT)
    if view.count:
        ev['x'], ev['y'] = _xy(raw, view)
        ev['sec'] = _field(raw, view, 4, '<u4')
        ev['nsec'] = _field(raw, view, 8, '<u4')
        ev['p'] = _field(raw, view, 12, 'u1')
    return (struct.pack('<I', seq) + bytes(raw[4:12]) + struct.pack('<I', len(frame)) + frame
            + struct.pack('<III', view.height, view.width, view.count) + ev.tobytes())
