"""The message path of ``evsync_node`` and of its camera processes: each event message decoded,
counted and restamped with its camera's correction (or what ``before_lock`` says before the lock),
companions restamped with their camera, held messages released. It is an object its node owns:
where a message's event times go is its ``Sink``, where its correction comes from its
``Corrections``."""

from __future__ import annotations

import struct
import time
from collections.abc import Callable
from typing import Any, Protocol

from rclpy.duration import Duration

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.density import TimeArray
from evsync_ros.ros.modes import BeforeLock
from evsync_ros.ros.streams import LATENCY_SAMPLES, CompanionState, StreamState
from msg_adapters.edges import TriggerEdges
from msg_adapters.events import Stepped
from msg_adapters.header import message_key, restamp_header
from msg_adapters.registry import camera_model

__all__ = ['UNSHIFTED', 'Corrections', 'MessagePath', 'Sink', 'stamp_ns']

UNSHIFTED = ClockCorrection(offset_ns=0)
"""What a camera's messages get before its lock (forwarded, or held too long). They still pass through
its restamper, which must see every message in order: an evt3 consumer anchors sensor time on the
first message it gets, so the restamper's output anchor has to be that same message's (a lock that
only moved header.stamp afterwards would never reach the events)."""
BURST_WAIT_S = 2.0
"""How long a backlog going out at once waits in all, a half history at a time, for its subscribers'
acknowledgements (a subscriber that never acknowledges stalls the node no longer than this)."""


class Corrections(Protocol):
    """Where a camera's correction comes from: the estimate in the node's process, or what the
    estimator process last published to a camera process."""

    def correction(self, topic: str) -> ClockCorrection | None:
        """What its messages get now (None: not locked)."""

    def coarse(self, topic: str) -> ClockCorrection | None:
        """``before_lock: coarse``: the offset seen in arrival times (None while not known)."""

    def passthrough(self, topic: str) -> bool:
        """Its messages go out with no correction (the reference, unless the rig is on host time);
        they still pass its restamper, for the stamp rule (docs/messages.md)."""


class Sink(Protocol):
    """Where a message's event times go."""

    def feed(self, st: StreamState, times: TimeArray, receipt: int, raw: bytes) -> None:
        """One message's event times (``receipt``: when it arrived, on the arrival clock)."""

    def modelled(self, st: StreamState) -> None:
        """The stream's camera model is known (``st.model``, from its first decoded message)."""

    def counted(self, st: StreamState, step: Stepped, receipt: int, raw: bytes) -> None:
        """``feed``, for a message decoded in one C call: its times, and its events already counted on
        the grid of the path's ``grid_ns`` (``Stepped.counts``)."""

    def edges(self, st: StreamState, edges: TriggerEdges) -> None:
        """One message's trigger edges on the stream's ``trigger_channel``."""


class MessagePath:
    """Streams and companions in, restamped out (module notes)."""

    def __init__(self, *, corrections: Corrections, sink: Sink, clock: Callable[[], int], before_lock: BeforeLock,
                 hold_limit_ns: int, qos_depth: int, grid_ns: int, warn: Callable[[str], None]) -> None:
        """``clock``: when a message arrives (ns); ``grid_ns``: the estimate's grid, on which messages
        decoded in one C call are counted; ``warn``: a line for the node's log."""
        self.corrections = corrections
        self.sink = sink
        self.clock = clock
        self.before_lock = before_lock
        """What a camera's messages get before its lock (``ros2 param set`` changes it)."""
        self.hold_limit_ns = hold_limit_ns
        self.qos_depth = qos_depth
        self.grid_ns = grid_ns
        self.warn = warn
        self.streams: dict[str, StreamState] = {}
        self.companions: dict[str, CompanionState] = {}
        self._before = {BeforeLock.COARSE: self._coarse, BeforeLock.HOLD: self._hold,
                        BeforeLock.FORWARD: self._forward}
        """How a message goes out before its camera's lock, by mode."""

    # -- event messages ---------------------------------------------------------------------------

    def on_message(self, st: StreamState, raw: bytes) -> None:
        """An event message of ``st``'s camera, as it came (serialized)."""
        start = time.perf_counter_ns()
        receipt = self.clock()
        st.received += 1
        key, stamp = message_key(raw)
        if st.seen(key):
            st.duplicates += 1  # each message goes out once: a second delivery is counted, not republished
            return
        if stamp is not None and st.last_stamp is not None and stamp < st.last_stamp:
            st.out_of_order += 1
        st.last_stamp = stamp
        going = self._going_out(st)
        try:
            step = None if not st.model else st.decoder.step(
                raw, grid_ns=self.grid_ns, counts=st.counts, restamper=st.restamper.packets, correction=going,
                edges=st.trigger_channel is not None)
            if step is not None:  # one C call: decoded, counted on the grid, restamped when ``going``
                times, view = step.times, None
                self._edges(st, step.edges)
            elif st.trigger_channel is not None and st.model:  # its edges too (``trigger_channels``)
                times, edges = st.decoder.decode_times_edges(raw)
                view = None
                self._edges(st, edges)
            elif st.model or not st.msgtype:  # the estimate's decode (``bag.estimate``): times alone
                times, view = st.decoder.decode_times(raw), None
            else:  # its first message: what camera it is, from its fields
                view, events = st.decoder.decode(raw)
                times = events.t
        except Exception as exc:  # noqa: BLE001 (whatever the bytes, the message is counted and goes on)
            st.malformed += 1
            st.last_error = f'message {st.received}: {exc}'
            self._publish(st, raw, start)  # unchanged: counted, not dropped
            return
        if times.size:
            st.last_time_ns = int(times[-1])
            if st.timed:
                st.times.add(times, receipt)
        if view is not None:
            st.model = camera_model(st.msgtype, view)
            self.sink.modelled(st)
        if step is not None:
            self.sink.counted(st, step, receipt, raw)
        else:
            self.sink.feed(st, times, receipt, raw)
        if st.publisher is None:  # republish none: the estimate is all this message was for
            return
        if step is None or going is None:
            self._out(st, raw, receipt, start)
        elif step.out is None:
            self._unrestamped(st, step.error)
            self._publish(st, raw, start)
        else:
            self._publish(st, bytes(step.out), start)

    def _edges(self, st: StreamState, edges: TriggerEdges | None) -> None:
        """A message's trigger edges, those on the stream's ``trigger_channel`` to the sink."""
        if edges is not None and st.trigger_channel is not None:
            edges = edges.on_channel(st.trigger_channel)
            if len(edges):
                self.sink.edges(st, edges)

    def _going_out(self, st: StreamState) -> ClockCorrection | None:
        """The correction a message of ``st`` goes out with, known before it is decoded (its camera
        locked, passed through, forwarded, or before its lock the coarse offset) and nothing is held
        before it (the restamper must see the stream in order); else None. (A message whose events show
        a clock jump still goes out with the lock it had, and one before the lock with the coarse offset
        the arrivals before it gave: the next goes out as the lock and the arrivals then say.)"""
        if st.publisher is None or st.held:
            return None
        if self.corrections.passthrough(st.topic):
            return UNSHIFTED
        correction = self.corrections.correction(st.topic)
        if correction is not None:
            return correction
        if self.before_lock is BeforeLock.COARSE:
            return self.corrections.coarse(st.topic)  # None until the reference has sent: then held
        return UNSHIFTED if self.before_lock is BeforeLock.FORWARD else None

    def _out(self, st: StreamState, raw: bytes, receipt: int, start: int) -> None:
        """A decoded message restamped and published as its camera's state says (or held)."""
        if self.corrections.passthrough(st.topic):  # the rig's timeline: no correction, but the one stamp rule
            self._restamp_and_publish(st, raw, UNSHIFTED, start)
            return
        correction = self.corrections.correction(st.topic)
        if correction is None:
            self._before[self.before_lock](st, raw, receipt, start)
            return
        if st.held:
            self._flush(st, correction)
        self._restamp_and_publish(st, raw, correction, start)

    def _coarse(self, st: StreamState, raw: bytes, receipt: int, start: int) -> None:
        coarse = self.corrections.coarse(st.topic)
        if coarse is None:  # the arrival offset needs a message of the reference: held until then
            self._hold(st, raw, receipt, start)
            return
        if st.held:
            self._flush(st, coarse)
        self._restamp_and_publish(st, raw, coarse, start)

    def _hold(self, st: StreamState, raw: bytes, receipt: int, start: int) -> None:
        st.held.append((receipt, raw))
        self._release_overdue(st, receipt)

    def _forward(self, st: StreamState, raw: bytes, receipt: int, start: int) -> None:
        self._restamp_and_publish(st, raw, UNSHIFTED, start)

    def _release_overdue(self, st: StreamState, now: int | None) -> None:
        """Held messages older than hold_limit (None: every one) go out unshifted."""
        while st.held and (now is None or now - st.held[0][0] > self.hold_limit_ns):
            _, raw = st.held.popleft()
            st.released_unshifted += 1
            self._restamp_and_publish(st, raw, UNSHIFTED, None)

    def _flush(self, st: StreamState, correction: ClockCorrection) -> None:
        sent, until = 0, time.monotonic() + BURST_WAIT_S
        while st.held:
            _, raw = st.held.popleft()
            self._restamp_and_publish(st, raw, correction, None)
            sent = self._paced(st.publisher, sent, until)

    def _restamp_and_publish(self, st: StreamState, raw: bytes, correction: ClockCorrection, start: int | None) -> None:
        try:
            out = bytes(st.restamper.restamp(raw, correction))
        except Exception as exc:  # noqa: BLE001 (as above)
            self._unrestamped(st, str(exc))
            out = raw
        self._publish(st, out, start)

    @staticmethod
    def _unrestamped(st: StreamState, why: str) -> None:
        st.unrestamped += 1
        st.last_error = f'message {st.received}: cannot restamp: {why}'

    def _publish(self, st: StreamState, raw: bytes, start: int | None) -> None:
        if st.publisher is None:  # republish none
            return
        st.publisher.publish(raw)
        st.published += 1
        if start is not None:
            st.latency_ns[st.latency_count % LATENCY_SAMPLES] = time.perf_counter_ns() - start
            st.latency_count += 1

    def _paced(self, publisher: Any, sent: int, until: float) -> int:
        """Count a message of a backlog going out at once (held until the lock); every half of the
        output's history, wait until its subscribers have acknowledged it all, while ``until``
        (monotonic s) has not passed: a reliable output keeps only the last ``qos_depth`` messages,
        and a burst larger than that would overwrite what a slower subscriber has not yet taken.
        Best effort returns at once."""
        sent += 1
        left = until - time.monotonic()
        if publisher is not None and left > 0 and sent % max(1, self.qos_depth // 2) == 0:
            publisher.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9)))
        return sent

    # -- companions -------------------------------------------------------------------------------

    def on_companion(self, cs: CompanionState, raw: bytes) -> None:
        """A companion's message: its camera's correction now, or what its camera's messages get
        before the lock (held with ``hold`` until the lock, or the hold limit)."""
        receipt = self.clock()
        cs.received += 1
        off = cs.stamps.check(stamp_ns(raw[4:12]), receipt, self.streams[cs.camera].times) if len(raw) >= 12 else None
        if off is not None and cs.stamps.disagreeing == 1:  # said once here; /diagnostics keeps saying it
            self.warn(cs.stamps.says())
        correction = self._companion_correction(cs)
        if correction is None:
            cs.held.append((receipt, raw))
            self._release_companion(cs, receipt)
            return
        if cs.held:
            self._flush_companion(cs, correction)
        self._publish_companion(cs, raw, correction)

    def _companion_correction(self, cs: CompanionState) -> ClockCorrection | None:
        """What a companion's message gets now (None: held)."""
        if self.corrections.passthrough(cs.camera):
            return UNSHIFTED
        correction = self.corrections.correction(cs.camera)
        if correction is not None or self.before_lock is BeforeLock.HOLD:
            return correction
        return UNSHIFTED if self.before_lock is BeforeLock.FORWARD else self.corrections.coarse(cs.camera)

    def _publish_companion(self, cs: CompanionState, raw: bytes, correction: ClockCorrection) -> None:
        try:
            out = restamp_header(raw, correction, what=f'message {cs.received} of {cs.topic}')
            cs.applied = correction
        except Exception as exc:  # noqa: BLE001 (counted and published unchanged, as event messages are)
            cs.malformed += 1
            cs.last_error = str(exc)
            out = raw
        cs.publisher.publish(out)
        cs.published += 1

    def _release_companion(self, cs: CompanionState, now: int | None) -> None:
        while cs.held and (now is None or now - cs.held[0][0] > self.hold_limit_ns):
            _, raw = cs.held.popleft()
            cs.released_unshifted += 1
            self._publish_companion(cs, raw, UNSHIFTED)

    def _flush_companion(self, cs: CompanionState, correction: ClockCorrection) -> None:
        sent, until = 0, time.monotonic() + BURST_WAIT_S
        while cs.held:
            _, raw = cs.held.popleft()
            self._publish_companion(cs, raw, correction)
            sent = self._paced(cs.publisher, sent, until)

    # -- what was held ----------------------------------------------------------------------------

    def release_held(self, now: int) -> None:
        """Held messages go out with their camera's lock (or the coarse offset), else past the hold limit."""
        for st in self.streams.values():
            if not st.held:
                continue
            correction = self.corrections.correction(st.topic)
            if correction is None and self.before_lock is BeforeLock.COARSE:
                correction = self.corrections.coarse(st.topic)
            if correction is not None:
                self._flush(st, correction)
            else:
                self._release_overdue(st, now)
        for cs in self.companions.values():
            if cs.held:
                correction = self._companion_correction(cs)
                if correction is not None:
                    self._flush_companion(cs, correction)
                else:
                    self._release_companion(cs, now)

    def flush_held(self) -> int:
        """Publish every held message (on shutdown: nothing is lost): restamped when its camera is
        locked, else unshifted and counted. Returns how many went out."""
        n = 0
        for st in self.streams.values():
            correction = self.corrections.correction(st.topic)
            n += len(st.held)
            if correction is not None:
                self._flush(st, correction)
            else:
                self._release_overdue(st, None)
        for cs in self.companions.values():
            n += len(cs.held)
            correction = self._companion_correction(cs)
            if correction is not None:
                self._flush_companion(cs, correction)
            else:
                self._release_companion(cs, None)
        return n


def stamp_ns(stamp: bytes) -> int:
    """header.stamp in ns, from its 8 bytes in a message (after the CDR header)."""
    sec, nanosec = struct.unpack('<iI', stamp)
    return sec * 1_000_000_000 + nanosec
