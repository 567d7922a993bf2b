"""Writing a restamped copy of a rosbag2: every event topic onto the reference timeline. The input is
only read; the output is written through ``BagWriter`` (nothing partial is left). What moves, per
type, and what happens to record timestamps: docs/bags.md, "restamp"."""

from __future__ import annotations

import enum
import importlib.metadata
import struct
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag1,
    ConnectionExtRosbag2,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.base import TypesysError
from rosbags.typesys.store import Typestore

from evsync_ros.bag import pipeline, records, ros1
from evsync_ros.bag.events import trigger_topics
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.records import NO_STAMP, ROW_CHANNEL, ROW_LENGTH, ROW_LOG, ROW_OFFSET, Chunk
from evsync_ros.bag.stampcheck import CameraTimes, StampCheck
from evsync_ros.bag.storage import ROSBAG2, Storage, output_storage
from evsync_ros.bag.writer import BagWriter, Layout
from evsync_ros.core.clock import ClockCorrection, CorrectionTrack
from evsync_ros.core.host import HOST
from evsync_ros.core.results import load_rig
from evsync_ros.errors import BagError, MessageError, ParameterError
from msg_adapters.cdr import read_stamp
from msg_adapters.definitions import event_typestore
from msg_adapters.header import restamp_header
from msg_adapters.registry import Restamper, decoder_for, is_event_type, restamp

SAME_CLOCK_NS = 1_000_000_000
"""header.stamp and the record timestamp this close: the driver stamps with the recorder's clock."""


class RecordTime(str, enum.Enum):
    """Whether record timestamps of restamped topics move with header.stamp (docs/bags.md)."""

    AUTO = 'auto'
    """Moved when the header is stamped with the recorder's clock."""
    SHIFT = 'shift'
    KEEP = 'keep'

    @classmethod
    def of(cls, value: object) -> RecordTime:
        """``value`` as a record-time mode (ParameterError naming the choices otherwise)."""
        try:
            return cls(value)
        except ValueError:
            raise ParameterError(f'record_time must be one of {", ".join(RECORD_TIME)}, got {value!r}') from None


RECORD_TIME = tuple(m.value for m in RecordTime)
ROS1_TIME_END = (1 << 32) * 1_000_000_000
"""A ROS 1 bag's record times are uint32 seconds and nanoseconds: they end before this."""
_FOREVER = QosTime(2147483647, 4294967295)
LATCHED = Qos(QosHistory.UNKNOWN, 0, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, _FOREVER, _FOREVER,
              QosLiveliness.AUTOMATIC, _FOREVER, avoid_ros_namespace_conventions=False)
"""The QoS a latched ROS 1 topic is offered with in a rosbag2 output (as rosbags-convert does)."""


@dataclass
class TopicCopy:
    """What restamping did to one topic."""

    msgtype: str
    record_shifted: bool | None = None
    """Whether record timestamps moved with header.stamp (None: nothing restamped)."""
    messages_in: int = 0
    messages_out: int = 0
    restamped: int = 0
    unchanged_bad: int = 0
    """Event messages the adapter could not restamp, written unchanged."""
    unconvertible: int = 0
    """Messages of a ROS 1 input that do not match their definition, so have no CDR to write into a
    rosbag2 output: counted here, not written (a ROS 1 output takes them unchanged)."""
    first_error: str = ''
    stamps: StampCheck | None = None
    """A companion's stamps checked against its camera's event times (``stampcheck``)."""


@dataclass
class RestampReport:
    """What ``restamp_bag`` wrote."""

    output: Path
    storage: Storage
    topics: dict[str, TopicCopy] = field(default_factory=dict)
    stale_removed: list[Path] = field(default_factory=list)
    """Partial outputs that killed runs for the same output left, removed."""
    provenance: dict[str, Any] | None = None
    """What the output's metadata records of how it was made (None: a ROS 1 bag, which has no place
    for it)."""
    previous: dict[str, Any] | None = None
    """The input's own provenance: it was restamped by evsync already."""
    files: list[str] = field(default_factory=list)
    """A rosbag2 output's storage files (several: split; ``.zstd``: compressed whole)."""

    @property
    def bad(self) -> int:
        """Messages written unchanged because they could not be restamped, or not written because
        they could not be converted."""
        return sum(t.unchanged_bad + t.unconvertible for t in self.topics.values())


def load_offsets(path: str | Path) -> tuple[str, dict[str, ClockCorrection]]:
    """(reference, {topic: correction}) from the JSON of ``evsync estimate --json``
    (``results.load_rig``: ParameterError naming the file when it is not one)."""
    rig = load_rig(path)
    return rig.reference, rig.corrections


OFFSETS_TOPIC = '/evsync/offsets'
"""Where evsync_node publishes its corrections (``sensor_msgs/TimeReference``, one per camera and report)."""


def load_offsets_stream(bag: str | Path, *, topic: str = OFFSETS_TOPIC
                        ) -> dict[str, CorrectionTrack]:
    """Each camera's correction as the node knew it while the bag was recorded: its TimeReference
    samples on ``topic`` (``source`` the camera's topic, ``time_ref`` its own time, ``header.stamp``
    the rig's) as a ``CorrectionTrack``. BagError naming the bag when the topic is missing, of
    another type, or holds no sample."""
    with BagReader(bag) as reader:
        conn = next((c for c in reader.connections if c.topic == topic), None)
        if conn is None:
            raise BagError(f'{bag}: no {topic} topic to take the offsets from')
        if conn.msgtype != 'sensor_msgs/msg/TimeReference':
            raise BagError(f'{bag}: {topic} is {conn.msgtype}, not sensor_msgs/msg/TimeReference')
        store = get_typestore(Stores.ROS2_JAZZY)
        samples: dict[str, tuple[list[int], list[int]]] = {}
        for _, _, raw in reader.messages([topic]):
            if isinstance(raw, ros1.Unconverted):
                raise BagError(f'{bag}: a message of {topic} does not match its definition ({raw.error})')
            try:
                msg: Any = store.deserialize_cdr(bytes(raw), conn.msgtype)
            except (SerdeError, ValueError, IndexError) as exc:
                raise BagError(f'{bag}: a message of {topic} cannot be read ({exc})') from exc
            own, rig = samples.setdefault(msg.source, ([], []))
            own.append(msg.time_ref.sec * 1_000_000_000 + msg.time_ref.nanosec)
            rig.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
    if not samples:
        raise BagError(f'{bag}: {topic} holds no offsets')
    return {t: CorrectionTrack(np.array(o), np.array(r), topic=t) for t, (o, r) in samples.items()}


def _definition(conn: Connection, types: Typestore | None, *, bag: Path) -> tuple[str, str]:
    """(msgdef, rihs01) for a rosbag2 writer: the input's own, else generated from a typestore that
    knows it (a ROS 1 input's types: ROS 2's where they are the same, else its own; None: a
    rosbag2's, the event types and ROS 2 Jazzy's); BagError naming ``bag`` when none can be had."""
    msgdef, digest = conn.msgdef.data, conn.digest
    if ros1.is_ros1_connection(conn):
        msgdef, digest = '', ''
    if msgdef and digest:
        return msgdef, digest
    types = types or event_typestore()
    for store in (event_typestore(), get_typestore(Stores.ROS2_JAZZY), types):
        if conn.msgtype in store.fielddefs and _same_fields(store, types, conn.msgtype):
            generated, _ = store.generate_msgdef(conn.msgtype, ros_version=2)
            try:
                return msgdef or generated, digest or store.hash_rihs01(conn.msgtype)
            except TypesysError:
                continue
    raise BagError(f'{bag}: topic {conn.topic}: type {conn.msgtype or "(none)"} comes without a definition or hash, '
                   'and evsync_ros knows no definition of it to write one')


class _HeaderRestamper:
    """A companion topic's restamper: header.stamp only."""

    def __init__(self, topic: str) -> None:
        self.what = f'a message of {topic}'

    def restamp(self, raw: bytes | bytearray | memoryview, correction: ClockCorrection) -> bytes:
        return restamp_header(raw, correction, what=self.what)


def _same_fields(store: Typestore, types: Typestore, msgtype: str) -> bool:
    """Whether ``store`` defines ``msgtype`` as the input's own types do (field names compared as
    ROS 1 and ROS 2 spell them; a type the input does not define: yes)."""
    theirs = types.fielddefs.get(msgtype)
    if theirs is None or store is types:
        return True
    return [(n.lower(), d) for n, d in store.fielddefs[msgtype][1]] == [(n.lower(), d) for n, d in theirs[1]]


def _ros1_to_cdr(types: Typestore, raw: bytes, msgtype: str) -> bytes:
    """A ROS 1 message as CDR; MessageError (the message is written unchanged) when it does not match
    its definition."""
    try:
        return ros1.to_cdr(types, raw, msgtype)
    except (SerdeError, MessageError) as exc:
        raise MessageError(f'does not match its definition of {msgtype} ({exc})') from exc


def _serialization(conn: Connection) -> tuple[str, list[Qos]]:
    """(serialization format, offered QoS profiles) of an input topic, as its bag records them (a
    latched ROS 1 topic: transient local, as rosbags-convert offers it)."""
    if isinstance(conn.ext, ConnectionExtRosbag2):
        return conn.ext.serialization_format, list(conn.ext.offered_qos_profiles)
    if isinstance(conn.ext, ConnectionExtRosbag1) and conn.ext.latching:
        return 'cdr', [LATCHED]
    return 'cdr', []


def _latched(conn: Connection) -> bool:
    """Whether an input topic is latched (ROS 1) or offered transient local (rosbag2)."""
    if isinstance(conn.ext, ConnectionExtRosbag1):
        return bool(conn.ext.latching)
    return any(q.durability is QosDurability.TRANSIENT_LOCAL for q in _serialization(conn)[1])


def _same_clock(reader: BagReader, topics: list[str]) -> dict[str, bool]:
    """Per topic, whether its first decodable header.stamp is within SAME_CLOCK_NS of its record time."""
    out: dict[str, bool] = {}
    for conn, timestamp, raw in reader.messages(topics):
        if conn.topic not in out:
            try:  # a well-formed event message, or one that begins with a Header?
                if is_event_type(conn.msgtype):
                    restamp(raw, conn.msgtype, ClockCorrection(offset_ns=0))
                else:
                    restamp_header(raw, ClockCorrection(offset_ns=0))
            except MessageError:
                continue
            out[conn.topic] = abs(timestamp - read_stamp(raw)) < SAME_CLOCK_NS
            if len(out) == len(topics):
                break
    return out


def check_companions(companions: Mapping[str, str], conns: Mapping[str, Connection], types: Typestore, *,
                     bag: Path, cameras: Iterable[str]) -> None:
    """BagError naming the companion unless each is a topic of the bag whose type begins with a
    std_msgs/Header, and its camera (the value) is one of ``cameras``."""
    known = set(cameras)
    for topic, camera in companions.items():
        if topic not in conns:
            raise BagError(f'{bag}: no companion topic {topic} (topics: {", ".join(sorted(conns))})')
        msgtype = conns[topic].msgtype
        if is_event_type(msgtype):
            raise BagError(f'{bag}: companion {topic} is an event topic ({msgtype}); it gets its own offset')
        if camera not in known:
            raise BagError(f'{bag}: companion {topic} names {camera}, which is not an event topic being '
                           f'synchronised ({", ".join(sorted(known))})')
        if not ros1.leading_header(types, msgtype):
            raise BagError(f'{bag}: companion {topic} has type {msgtype}, which does not begin with a '
                           'std_msgs/Header: there is no header.stamp to restamp')


def evsync_version() -> str:
    """The installed evsync_ros's version ('unknown' when it is not installed)."""
    try:
        return importlib.metadata.version('evsync_ros')
    except importlib.metadata.PackageNotFoundError:
        return 'unknown'


def restamp_bag(src: str | Path, dst: str | Path, *, corrections: Mapping[str, ClockCorrection],
                reference: str, storage: Storage | str | None = None, record_time: RecordTime | str = RecordTime.AUTO,
                companions: Mapping[str, str] | None = None,
                progress: Callable[[int, int], None] | None = None,
                provenance: Mapping[str, Any] | None = None,
                tracks: Mapping[str, CorrectionTrack] | None = None, parallel: bool | None = None,
                layout: Layout = Layout()) -> RestampReport:
    """Write ``dst``: ``src`` with each topic in ``corrections`` restamped (docs/bags.md).

    Args:
        src: the input bag (only read).
        dst: the output bag; it must not exist, nor be the input or inside it.
        corrections: per event topic, the correction onto the reference timeline.
        reference: the reference topic (restamped with no correction: its header.stamp takes the
            rule every output takes, docs/messages.md), or ``host`` (every camera restamped onto host time).
        storage: sqlite3 or mcap (default: the input's; mcap for a ROS 1 input); an output
            ending in .bag is a ROS 1 bag, whatever the input.
        record_time: 'auto', 'shift' or 'keep': whether record timestamps move with header.stamp.
        companions: {topic: event topic}: topics on an event camera's clock (its IMU, frames,
            camera_info: any type that begins with a std_msgs/Header), whose header.stamp gets
            that camera's correction, every other byte kept.
        progress: called as ``progress(done, total)`` while messages are written.
        tracks: per event topic, its correction as it changed over time (``load_offsets_stream``:
            what the node knew, drift included), in place of ``corrections`` for that topic: each
            message (and each of its companions') gets the correction around its header.stamp.
        provenance: more to record in the output's metadata (the estimate in the JSON contract,
            the method) beside what is always recorded: the evsync version, the input, the
            reference, the corrections and companions applied, when (``RestampReport.provenance``).
        parallel: whether an input copied a chunk at a time (mcap, sqlite3 and ROS 1 files) is
            read and restamped in a second process while this one writes (the same output either
            way; docs/bags.md, "Speed"). None: where a second core is free and no other thread runs
            (``pipeline.available``).
        layout: a rosbag2 output's compression and splitting (``writer.Layout``; default: one file).

    Returns:
        A ``RestampReport``: per topic, messages in and out, restamped, written unchanged (bad);
        what was recorded of the provenance, and the input's own when it was restamped already.

    Raises:
        BagError: the input cannot be read, the output exists or cannot be written, a corrected
            topic is missing or is not an event type, a companion is missing, has no leading
            Header or names no camera being synchronised, the layout cannot be written there.
        ParameterError: ``record_time`` is not one of its choices.
    """
    mode = RecordTime.of(record_time)
    tracks = dict(tracks or {})
    corrections = {**corrections, **{t: track.at(int(track.own_ns[0])) for t, track in tracks.items()}}
    src, dst = Path(src), Path(dst)
    out_storage = _output_storage(src, dst, storage)
    report = RestampReport(dst, out_storage)
    with BagReader(src) as reader:
        conns = {c.topic: c for c in reader.connections}
        _check_topics(src, conns, corrections, reference)
        total = sum(reader.message_counts().values())
        companions = dict(companions or {})
        # the input's types: to convert to or from ROS 1 (rosbag2 to rosbag2 converts nothing, and
        # needs a typestore only for a topic with no definition: made then), and to tell whether a
        # companion's type begins with a Header
        types = reader.typestore or (ros1.typestore_for(reader.connections)
                                     if out_storage is Storage.ROS1 or companions else None)
        if types is not None:
            check_companions(companions, conns, types, bag=src, cameras={*corrections, reference})
        # every camera's messages, the reference's too (with no correction), take the one rule for
        # header.stamp (docs/messages.md); a companion moves only with a correction
        cameras = {**({reference: ClockCorrection(offset_ns=0)} if reference in conns else {}), **corrections}
        cameras = {t: c for t, c in cameras.items() if is_event_type(conns[t].msgtype)}
        # a camera's trigger edges (a topic of their own) move with its events
        edges = {t: cam for t, cam in trigger_topics(reader).items() if cam in cameras and t not in cameras}
        camera_of = {t: t for t in cameras} | edges | companions
        active = {t: cameras[cam] for t, cam in camera_of.items()
                  if cam in cameras and (t not in companions or not cameras[cam].is_identity)}
        shift = _shifted(reader, mode, active, reference)
        native = reader.storage is Storage.ROS1 and out_storage is Storage.ROS1  # ROS 1 to ROS 1: bytes as they are
        report.previous = reader.provenance
        record = _record(src, reference, corrections, tracks=tracks, companions=companions, mode=mode,
                         provenance=provenance)
        with BagWriter(dst, storage=out_storage, typestore=types, layout=layout) as writer:
            report.stale_removed = writer.removed_stale
            report.provenance = record if writer.set_provenance(record) else None
            out = _topics_of(writer, conns, types, bag=src)
            report.topics.update({topic: TopicCopy(conn.msgtype) for topic, conn in conns.items()})
            live = {t for t in active if camera_of[t] in tracks}
            restampers = _restampers(conns, active, companions=companions, live=live)
            as_ros1 = {t: r for t, r in restampers.items()
                       if isinstance(r, Restamper) and native and types is not None
                       and ros1.adapters_convert(types, r.msgtype)}
            plan = _Plan(report, out, active, restampers, shift, tracks=tracks, camera_of=camera_of, native=native,
                         input_types=types, as_ros1=as_ros1,
                         time_end=ROS1_TIME_END if out_storage is Storage.ROS1 else 1 << 63)
            _copy(reader, writer, plan, companions=companions, progress=progress, total=total, parallel=parallel)
            if companions and report.provenance is not None:
                record['companion_stamps'] = {t: report.topics[t].stamps.as_json()  # type: ignore[union-attr]
                                              for t in companions}
                writer.set_provenance(record)
    report.files = writer.files
    return report


def _record(src: Path, reference: str, corrections: Mapping[str, ClockCorrection], *,
            tracks: Mapping[str, CorrectionTrack], companions: Mapping[str, str], mode: RecordTime,
            provenance: Mapping[str, Any] | None) -> dict[str, Any]:
    """What a rosbag2 output's metadata records of how it was made (``RestampReport.provenance``)."""
    return {'evsync_version': evsync_version(), 'input': str(src.resolve()), 'reference': reference,
            'corrections': {t: {'offset_ns': c.offset_ns, 'skew_ppm': c.skew_ppm, 'anchor_ns': c.anchor_ns}
                            for t, c in corrections.items() if t not in tracks},
            'offsets_stream': {t: len(track) for t, track in tracks.items()},
            'companions': dict(companions), 'record_time': mode.value,
            'written_utc': datetime.now(timezone.utc).isoformat(timespec='seconds'), **(provenance or {})}


def _restampers(conns: Mapping[str, Connection], active: Mapping[str, ClockCorrection], *,
                companions: Mapping[str, str], live: set[str]) -> dict[str, Restamper | _HeaderRestamper]:
    """Each restamped topic's restamper: an event topic's by its type, a companion's its header's. A
    correction that changes from message to message (a track, ``live``) must reach evt3 consumers,
    who anchor once: the live node's restamper."""
    return {t: Restamper(conns[t].msgtype, live=t in live) if t not in companions else _HeaderRestamper(t)
            for t in active}


def _output_storage(src: Path, dst: Path, storage: Storage | str | None) -> Storage:
    """The output's storage: ROS 1 for a name ending in .bag, else ``storage``, else the input's;
    BagError naming ``dst`` when it is the input or inside it, or the storage is none of them."""
    if dst.resolve() == src.resolve() or src.resolve() in dst.resolve().parents:
        raise BagError(f'{dst}: the output must not be the input or inside it')
    if ros1.is_ros1(dst):
        if storage not in (None, Storage.ROS1):
            raise BagError(f'{dst}: a name ending in {ros1.SUFFIX} is a ROS 1 bag; storage {storage} is rosbag2\'s')
        return Storage.ROS1
    if storage is None:
        return output_storage(src)
    # a ROS 1 storage for a rosbag2's name: the writer refuses it, saying why
    return Storage.ROS1 if storage == Storage.ROS1 else Storage.of(storage, bag=dst, among=ROSBAG2)


def _check_topics(src: Path, conns: Mapping[str, Connection], corrections: Mapping[str, ClockCorrection],
                  reference: str) -> None:
    """BagError naming the input unless every corrected topic is in it, of an event type where it
    moves, and the reference is one of its topics (or the host)."""
    unknown = sorted(set(corrections) - set(conns))
    if unknown:
        raise BagError(f'{src}: no topic {", ".join(unknown)} to restamp (topics: {", ".join(sorted(conns))})')
    wrong = [t for t, c in corrections.items() if not c.is_identity and not is_event_type(conns[t].msgtype)]
    if wrong:
        raise BagError(f'{src}: {", ".join(wrong)} not an event message type; only event topics are restamped')
    if reference not in conns and reference != HOST:
        raise BagError(f'{src}: no reference topic {reference}')


def _shifted(reader: BagReader, mode: RecordTime, active: Mapping[str, ClockCorrection], reference: str
             ) -> dict[str, bool]:
    """Per restamped topic, whether its record timestamps move with header.stamp: as ``mode`` says,
    or (auto) when its header, and the reference's, is stamped with the recorder's clock."""
    if mode is not RecordTime.AUTO:
        return dict.fromkeys(active, mode is RecordTime.SHIFT)
    same = _same_clock(reader, sorted({*active, reference} - {HOST}))
    return {t: same.get(t, False) and (reference == HOST or same.get(reference, False)) for t in active}


def _topics_of(writer: BagWriter, conns: Mapping[str, Connection], types: Typestore | None, *, bag: Path
               ) -> dict[str, Connection]:
    """Each input topic's output topic: a ROS 1 bag's with its ROS 1 definition (its own where it has
    one) and latching; a rosbag2's with its definition, serialization and QoS (``_definition``)."""
    out = {}
    for topic, conn in conns.items():
        if writer.storage is Storage.ROS1:
            own = ros1.is_ros1_connection(conn)
            out[topic] = writer.add_topic(topic, conn.msgtype, msgdef=conn.msgdef.data if own else None,
                                          md5sum=conn.digest if own else None, latching=_latched(conn))
        else:
            msgdef, digest = _definition(conn, types, bag=bag)
            fmt, qos = _serialization(conn)
            out[topic] = writer.add_topic(topic, conn.msgtype, msgdef=msgdef, rihs01=digest,
                                          serialization_format=fmt, offered_qos_profiles=qos)
    return out


@dataclass
class _Plan:
    """What the copy does to each topic's messages."""

    report: RestampReport
    out: dict[str, Connection]
    """Each input topic's output topic."""
    active: dict[str, ClockCorrection]
    """The topics restamped, with their corrections (a camera's, for a companion)."""
    restampers: dict[str, Restamper | _HeaderRestamper]
    shift: dict[str, bool]
    """Whether a restamped topic's record timestamps move with it."""
    tracks: dict[str, CorrectionTrack]
    camera_of: dict[str, str]
    native: bool
    """ROS 1 to ROS 1: the messages' own bytes."""
    input_types: Typestore | None
    """The input's types, where they are needed (ROS 1, companions)."""
    as_ros1: dict[str, Restamper] = field(default_factory=dict)
    """Event topics whose ROS 1 bytes the adapters restamp as they are (ROS 1 to ROS 1)."""
    time_end: int = 1 << 63
    """The output's record times end before this: int64's end; a ROS 1 bag's, its uint32 seconds'."""

    @property
    def types(self) -> Typestore:
        """The input's types (a rosbag2 without companions: the event types and ROS 2 Jazzy's)."""
        return self.input_types or event_typestore()


def _copy_messages(reader: BagReader, writer: BagWriter, plan: _Plan, *, companions: Mapping[str, str],
                   progress: Callable[[int, int], None] | None, total: int) -> None:
    """Every message of ``reader`` into ``writer``, in the reader's order, restamped as ``plan`` says."""
    report, native, types = plan.report, plan.native, plan.types
    # each companion's stamps against its camera's event times (an old driver's wrong stamps)
    times = {cam: CameraTimes() for cam in companions.values()}
    decoders = {cam: decoder_for(report.topics[cam].msgtype) for cam in times}
    for topic, cam in companions.items():
        report.topics[topic].stamps = StampCheck(topic, cam)
    done = 0
    for conn, timestamp, raw in reader.messages(native=native):
        rep = report.topics[conn.topic]
        rep.messages_in += 1
        if isinstance(raw, ros1.Unconverted):
            rep.unconvertible += 1
            rep.first_error = rep.first_error or f'message {rep.messages_in}: {raw.error}'
            continue
        if conn.topic in times or rep.stamps is not None:
            _check_stamps(conn, timestamp, raw, rep, times, decoders, types=types if native else None)
        data: bytes | bytearray = raw
        if conn.topic in plan.active:
            timestamp, data = _restamp_one(conn, timestamp, raw, plan)
        if native:
            writer.write_ros1(plan.out[conn.topic], timestamp, data)
        else:  # a restamped bytearray as it is: the writer copies only what it holds
            writer.write(plan.out[conn.topic], timestamp, data)
        rep.messages_out += 1
        done += 1
        if progress is not None and done % 512 == 0:
            progress(done, total)
    if progress is not None:
        progress(done, total)


def _restamp_one(conn: Connection, timestamp: int, raw: bytes, plan: _Plan) -> tuple[int, bytes | bytearray]:
    """(record timestamp, data) of one message of a restamped topic: restamped, or as it was (counted
    bad, with why) when it cannot be."""
    rep = plan.report.topics[conn.topic]
    try:
        data, corr = _restamped(conn.topic, raw, plan.active[conn.topic], plan)
        rep.record_shifted = plan.shift[conn.topic]
        if rep.record_shifted:  # by the correction, not the stamp rule: order is kept
            moved = corr.apply_one(timestamp)
            if not 0 <= moved < plan.time_end:
                raise MessageError(_outside(timestamp, moved))
            timestamp = moved
        rep.restamped += 1
        return timestamp, data
    except MessageError as exc:
        rep.unchanged_bad += 1
        rep.first_error = rep.first_error or f'message {rep.messages_in}: {exc}'
        return timestamp, raw


def _restamped(topic: str, raw: bytes, corr: ClockCorrection, plan: _Plan
               ) -> tuple[bytes | bytearray, ClockCorrection]:
    """(data, the correction it took) of one message of a restamped topic (a track's correction at
    its stamp); MessageError when it cannot be restamped. ROS 1 to ROS 1: its own bytes restamped
    where the adapters do that (``Restamper.restamp_ros1``), else converted to CDR and back."""
    track = plan.tracks.get(plan.camera_of[topic])
    direct = plan.as_ros1.get(topic)
    if plan.native and track is None and direct is not None:
        ready = direct.restamp_ros1(raw, corr)
        if ready is not None:
            return ready, corr
    msgtype = plan.report.topics[topic].msgtype
    cdr = _ros1_to_cdr(plan.types, raw, msgtype) if plan.native else raw
    if track is not None:
        corr = track.at(read_stamp(cdr))
    new = plan.restampers[topic].restamp(cdr, corr)  # validates the message first
    return (ros1.to_ros1(plan.types, new, msgtype, like=raw) if plan.native else new), corr


def _outside(timestamp: int, moved: int) -> str:
    return f'record timestamp {timestamp} would move to {moved}, outside the bag\'s range'


def _copy(reader: BagReader, writer: BagWriter, plan: _Plan, *, companions: Mapping[str, str],
          progress: Callable[[int, int], None] | None, total: int, parallel: bool | None) -> None:
    """Every message of ``reader`` into ``writer``, restamped as ``plan`` says: a chunk at a time where
    it can (``_chunked``), else message by message; what the whole read passed over is refused
    (``BagReader.check_whole``: then no output is left)."""
    chunked = _chunked(reader, writer) if not (companions or plan.tracks) else None
    if chunked is not None:
        _copy_chunks(reader, chunked, plan, writer, progress=progress, total=total, forked=pipeline.chosen(parallel))
    else:
        _copy_messages(reader, writer, plan, companions=companions, progress=progress, total=total)
    reader.check_whole({t: c.messages_in for t, c in plan.report.topics.items()})


def _chunked(reader: BagReader, writer: BagWriter) -> Iterator[tuple[Chunk, dict[int, str]]] | None:
    """The input's chunks, each with its ids' topics, to copy a chunk at a time (``_copy_chunks``),
    when the output takes chunks of the input's encoding (``BagReader.chunks``): a rosbag2 into mcap
    or sqlite3, with topics of the types the bag's are; ROS 1 into ROS 1. None: message by message."""
    if not writer.takes_chunks or (reader.storage is Storage.ROS1) != (writer.storage is Storage.ROS1):
        return None
    return reader.chunks({c.topic: c.msgtype for c in reader.connections})


def _copy_chunks(reader: BagReader, chunks: Iterator[tuple[Chunk, dict[int, str]]], plan: _Plan,
                 writer: BagWriter, *, progress: Callable[[int, int], None] | None, total: int, forked: bool) -> None:
    """``_copy_messages`` a chunk at a time (``_chunked``): the same messages in the same order,
    restamped alike, written in chunks of the input's (sqlite3: rows a batch at a time;
    docs/bags.md, "Speed"). The chunks are read, restamped and built in a second process while this
    one writes them when ``forked`` (``BagReader.deliver``)."""
    last = 0

    def write(data: memoryview | bytes, meta: tuple[Any, ...]) -> None:
        nonlocal last
        ids, logs, places, last = meta
        if writer.takes_rows:  # places: each row's length
            writer.write_rows(ids, logs, records.unpacked(data, places))
        else:  # each record's offset
            writer.write_chunk(data, ids, logs, places)
        if progress is not None:
            progress(last, total)

    blocks = _blocks(chunks, plan, as_rows=writer.takes_rows)
    plan.report.topics.update(reader.deliver(blocks, write, result=lambda: plan.report.topics, forked=forked))
    if progress is not None:
        progress(last, total)


def _blocks(chunks: Iterator[tuple[Chunk, dict[int, str]]], plan: _Plan, *, as_rows: bool) -> Iterator[pipeline.Block]:
    """Each chunk with a row, restamped (``_restamp_chunk``), as a block of the output's records
    (``records.build``) whose meta is (ids, record times, offsets, messages so far); with ``as_rows``,
    of its messages' data one after another (``records.pack``), and each one's length for offsets."""
    done = 0
    for chunk, topic_of in chunks:
        if not len(chunk.rows):
            continue
        out_rows, logs, stamps, new = _restamp_chunk(chunk, topic_of, plan)
        done += len(out_rows)

        def fill(out: bytearray | memoryview, chunk: Chunk = chunk, rows: npt.NDArray[np.int64] = out_rows,
                 logs: npt.NDArray[np.int64] = logs, stamps: npt.NDArray[np.int64] = stamps,
                 new: list[bytes | bytearray | None] = new, done: int = done) -> tuple[int, tuple[Any, ...] | None]:
            size, places = (records.pack(chunk, rows, stamps, new, out=out) if as_rows
                            else records.build(chunk, rows, logs, stamps, new, out=out, ros1=plan.native))
            return size, None if places is None else (rows[:, ROW_CHANNEL], logs, places, done)

        yield pipeline.Block(fill)


def _restamp_chunk(chunk: Chunk, topic_of: dict[int, str], plan: _Plan
                   ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64],
                              list[bytes | bytearray | None]]:
    """(rows with the output's ids, record times, header.stamps, new data) of one chunk's rows
    (each source gives the rows of ``topic_of``'s ids alone), each topic's restamped
    (``_restamp_rows``)."""
    rows = chunk.rows
    logs = rows[:, ROW_LOG].copy()
    stamps = np.full(len(rows), NO_STAMP)
    new: list[bytes | bytearray | None] = [None] * len(rows)
    out_rows = rows.copy()
    channels = rows[:, ROW_CHANNEL]
    for topic in dict.fromkeys(topic_of[c] for c in np.unique(channels).tolist()):
        # a topic's messages in reading order, whatever ids (connections, channels) carry them
        at = np.flatnonzero(records.among(channels, (c for c, t in topic_of.items() if t == topic)))
        out_rows[at, ROW_CHANNEL] = plan.out[topic].id
        _restamp_rows(chunk, rows[at], at, topic, plan, logs=logs, stamps=stamps, new=new)
    return out_rows, logs, stamps, new


def _restamp_rows(chunk: Chunk, rows: npt.NDArray[np.int64], at: npt.NDArray[np.int64], topic: str,
                  plan: _Plan, *, logs: npt.NDArray[np.int64], stamps: npt.NDArray[np.int64],
                  new: list[bytes | bytearray | None]) -> None:
    """One topic's messages of a chunk (``rows``, at ``at`` among the chunk's), counted and, for a
    restamped topic, restamped as ``_restamp_one`` restamps each: into ``logs``, ``stamps`` and
    ``new`` at ``at``. The adapters' C path takes the messages in one call, for as long as it can; a
    message it leaves goes through ``Restamper.restamp``."""
    rep = plan.report.topics[topic]
    base = rep.messages_in
    rep.messages_in += len(rows)
    rep.messages_out += len(rows)
    corr = plan.active.get(topic)
    if corr is None:
        return
    restamper = plan.restampers[topic]
    assert isinstance(restamper, Restamper)  # companions go message by message
    rows = np.ascontiguousarray(rows)
    mine_stamps = np.full(len(rows), NO_STAMP)
    mine: list[bytes | bytearray | None] = [None] * len(rows)
    ok = np.zeros(len(rows), bool)
    errors: list[tuple[int, str]] = []
    i = 0
    batch = not plan.native or topic in plan.as_ros1  # ROS 1 bytes the adapters take as they are
    while i < len(rows):
        j = restamper.restamp_rows(chunk.data, rows, i, corr, stamps=mine_stamps, new=mine,
                                   ros1=plan.native) if batch else i
        ok[i:j] = True
        if j == len(rows):
            break
        o, n = int(rows[j, ROW_OFFSET]), int(rows[j, ROW_LENGTH])
        try:
            mine[j] = _restamped(topic, bytes(chunk.data[o:o + n]), corr, plan)[0]
            ok[j] = True
        except MessageError as exc:
            errors.append((j, str(exc)))
        i = j + 1
    if ok.any():
        rep.record_shifted = plan.shift[topic]
    if plan.shift[topic]:
        moved, inside = _record_times(corr, rows[:, ROW_LOG], end=plan.time_end)
        for j in np.flatnonzero(ok & ~inside).tolist():
            ok[j] = False
            errors.append((j, _outside(int(rows[j, ROW_LOG]), int(moved[j]))))
        logs[at[ok]] = moved[ok].astype(np.int64)
    if errors:
        j, why = min(errors)
        rep.first_error = rep.first_error or f'message {base + j + 1}: {why}'
    rep.unchanged_bad += len(errors)
    rep.restamped += int(ok.sum())
    stamps[at[ok]] = mine_stamps[ok]
    for j in np.flatnonzero(ok).tolist():
        if mine[j] is not None:
            new[at[j]] = mine[j]


def _record_times(corr: ClockCorrection, t: npt.NDArray[np.int64], *, end: int
                  ) -> tuple[npt.NDArray[Any], npt.NDArray[np.bool_]]:
    """(``corr.apply_one`` of each of ``t``, to the nanosecond; whether each is a record time, in
    [0, end)): ``corr.apply`` in int64 where nothing can overflow (a correction's offset and anchor
    are within 2^62 and its skew under 0.1), else as Python ints (an object array)."""
    if abs(corr.offset_ns) < 1 << 61 and (not t.size or int(t.max()) < 1 << 62):
        moved = corr.apply(t)
        return moved, (moved >= 0) & (moved < end)
    exact = [corr.apply_one(int(x)) for x in t.tolist()]
    return np.array(exact, dtype=object), np.array([0 <= m < end for m in exact], dtype=bool)


def _check_stamps(conn: Connection, record: int, raw: bytes, rep: TopicCopy, times: Mapping[str, CameraTimes],
                  decoders: Mapping[str, Any], *, types: Typestore | None) -> None:
    """A camera's event times taken, or a companion's stamp checked against them, each at its record
    time (``types``: a ROS 1 input's, whose messages are converted first). A message that cannot be
    read is left to the restamping, which counts it."""
    try:
        cdr = _ros1_to_cdr(types, raw, conn.msgtype) if types is not None else raw
        if conn.topic in times:
            times[conn.topic].add(decoders[conn.topic].decode_times(cdr), record)
        elif rep.stamps is not None:
            rep.stamps.check(read_stamp(cdr), record, times[rep.stamps.camera])
    except (MessageError, struct.error):
        return
