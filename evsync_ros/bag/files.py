"""What a bag is made of, as ``BagReader`` opens it: a rosbag2's storage files (through its
metadata.yaml, or file by file when rosbags' reader refuses the directory), each with the
connections a read of it yields (``Part``), what their own indexes list, and what reading would
pass over unseen."""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rosbags.interfaces import Connection
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.reader import DirectoryReader
from rosbags.rosbag2.storage_mcap import McapReader
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader
from rosbags.typesys.store import Typestore
from ruamel.yaml import YAML
from ruamel.yaml.error import YAMLError

from evsync_ros.bag.storage import SUFFIXES, Storage, input_storage
from evsync_ros.errors import BagError

if TYPE_CHECKING:
    from evsync_ros.bag.storage_ros1 import StreamingRos1

__all__ = ['PROVENANCE_KEY', 'Part', 'listed', 'listed_topics', 'parts_of', 'provenance', 'storage_files', 'storage_of',
           'unread_rows']

PROVENANCE_KEY = 'evsync'
"""The key of a restamped rosbag2's ``custom_data`` that says what evsync applied (JSON)."""


@dataclass(frozen=True)
class Part:
    """One storage file of a bag as a read goes through it (a ROS 1 bag: the bag), for its storage's
    plugin (``reader.PLUGINS``): the file, open; each id of it whose messages the read yields, with
    the connection it yields them as (rosbags' reader's: the bag's own where metadata.yaml lists it);
    the process that opened it; a ROS 1 bag's types, to convert its messages."""

    storage: Storage
    path: Path
    """The bag, as errors name it."""
    file: McapReader | Sqlite3Reader | StreamingRos1
    """rosbags' reader of the file, or a ROS 1 bag's ``StreamingRos1``."""
    conns: Mapping[int, Connection]
    pid: int
    typestore: Typestore | None = None


def storage_files(bag: Path) -> list[Path] | None:
    """The storage files of a bag whose metadata names no storage plugin, or that has no metadata.yaml
    (lost, or the recorder was killed before writing it), each with a suffix to tell its format by;
    None otherwise (rosbags' own reader reads it)."""
    meta = bag / 'metadata.yaml'
    if not meta.is_file():
        files = sorted((f for f in bag.iterdir() if f.suffix in SUFFIXES), key=_natural)
        if not files:
            raise BagError(f'{bag}: no metadata.yaml and no .mcap or .db3 storage file: not a rosbag2')
        return files
    try:
        info = YAML(typ='safe').load(meta.read_text())['rosbag2_bagfile_information']
        storage_id = info.get('storage_identifier')
        files = [bag / Path(p).name for p in info['relative_file_paths']]
    except (OSError, YAMLError, KeyError, TypeError, AttributeError):
        return None  # malformed metadata: rosbags' own reader reports it precisely
    if storage_id:
        return None
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        raise BagError(f'{bag}: storage files named in metadata.yaml are missing: {missing}')
    for f in files:
        if f.suffix not in SUFFIXES:
            raise BagError(f'{f}: metadata names no storage plugin and the file has no .mcap or .db3 suffix to '
                           'tell its format by')
    return files


def _natural(path: Path) -> tuple[int | str, ...]:
    """Sort key that puts rig_2.mcap before rig_10.mcap (a split recording's order)."""
    return tuple(int(part) if part.isdigit() else part for part in re.split(r'(\d+)', path.name))


def _matched(theirs: Iterable[Connection], ours: Iterable[Connection]) -> dict[int, Connection]:
    """{id: the bag's connection} of a storage file's connections that rosbags' ``DirectoryReader.messages``
    matches to one of the bag's (the first with the same topic, type, serialization and QoS, and
    hash where both have one), as it yields their messages."""
    ours = list(ours)
    out = {}
    for x in theirs:
        y = next((y for y in ours if y.topic == x.topic and y.msgtype == x.msgtype and y.ext == x.ext
                  and (not x.digest or not y.digest or y.digest == x.digest)), None)
        if y is not None:
            out[x.id] = y
    return out


def _files(reader: Reader) -> list[tuple[Any, dict[int, Connection]]]:
    """A rosbags reader's storage files, each with the connection it yields for each of its ids (a
    directory's files: those ``_matched`` to its metadata; a lone file: its own)."""
    storage = reader.storage
    if isinstance(storage, DirectoryReader):
        return [(s, _matched(s.connections, reader.connections)) for s in storage.storages]
    return [(storage, {c.id: c for c in storage.connections})]


def parts_of(readers: Iterable[Reader], *, path: Path, pid: int) -> list[Part] | None:
    """The storage files of ``readers`` (a bag's, open), in reading order, as ``Part``s; None when a
    file is neither mcap nor sqlite3 or the messages are compressed one by one (rosbags' reader
    reads such a bag whole)."""
    out = []
    for reader in readers:
        storage = reader.storage
        if isinstance(storage, DirectoryReader) and storage.metadata.compression_mode == 'message':
            return None
        for s, conns in _files(reader):
            if not isinstance(s, McapReader | Sqlite3Reader):
                return None
            out.append(Part(Storage.MCAP if isinstance(s, McapReader) else Storage.SQLITE3, path, s, conns, pid))
    return out


def storage_of(readers: list[Reader], bag: Path) -> Storage:
    """The storage of an open rosbag2's first storage file (unopened: as ``input_storage`` finds it)."""
    first = readers[0].storage if readers else None
    inner = first.storages[:1] if isinstance(first, DirectoryReader) else [first]
    if inner and isinstance(inner[0], McapReader | Sqlite3Reader):
        return Storage.MCAP if isinstance(inner[0], McapReader) else Storage.SQLITE3
    return input_storage(bag)


def listed(storage: McapReader | Sqlite3Reader) -> tuple[dict[int, int], bool]:
    """The messages per id (an mcap channel, a sqlite3 topic) that a storage file's own index lists, and
    whether they are per-id statistics that must add up to the file's count. An mcap file whose
    statistics leave the per-channel map empty ("not available", as the mcap spec allows) is
    counted from its chunk indexes instead, as rosbags counts a file with no statistics."""
    counts = {c.id: c.msgcount for c in storage.connections}
    stats = storage.statistics if isinstance(storage, McapReader) else None
    if stats is None or stats.channel_message_counts or not stats.message_count:
        return counts, True
    assert isinstance(storage, McapReader)  # only an mcap file has statistics
    from_chunks: dict[int, int] = {}
    for chunk in storage.chunks:
        for cid, n in chunk.channel_count.items():
            from_chunks[cid] = from_chunks.get(cid, 0) + n
    return from_chunks, False


def listed_topics(readers: Iterable[Reader]) -> list[tuple[str, int]]:
    """(topic, messages) of every id of ``readers``' storage files that a read yields, as the files'
    own indexes list them."""
    files = [(listed(s)[0], conns) for reader in readers for s, conns in _files(reader)]
    return [(conn.topic, counts.get(cid, 0)) for counts, conns in files for cid, conn in conns.items()]


def unread_rows(readers: Iterable[Reader]) -> list[str]:
    """What of the storage files no topic of the bag reaches, and reading would silently leave out:
    the messages of a file's topic (a sqlite3 topic, an mcap channel) that its metadata.yaml lists
    otherwise (type, serialization, QoS or hash: rosbags matches them, and reads none of one it
    does not match), and messages whose topic or channel id names none. From the counts rosbags
    makes as it opens a file (an mcap file's from its statistics)."""
    out = []
    for reader in readers:
        for s, ids in _files(reader):
            if not isinstance(s, Sqlite3Reader | McapReader):
                continue
            name = Path(str(s.path)).name
            counts, per_id = listed(s)
            out += [f'{counts.get(c.id, 0)} messages of {c.topic} in {name}, whose type or QoS there '
                    f'({c.msgtype or "none"}) is not what metadata.yaml says (one of them is corrupt, or the '
                    'file was rewritten under the old metadata.yaml; without it the files are read alone)'
                    for c in s.connections if c.id not in ids and counts.get(c.id, 0)]
            orphans = s.metadata.message_count - sum(counts.values()) if per_id else 0
            if orphans > 0:
                what = 'channel' if isinstance(s, McapReader) else 'topic'
                out.append(f'{orphans} messages in {name} whose {what} id names no {what} (a damaged record or '
                           'index, or a layout the readers cannot read)')
    return out


def provenance(bag: Path) -> dict[str, Any] | None:
    """What evsync applied to make the rosbag2 ``bag`` (``BagWriter.set_provenance``): its
    ``custom_data`` key ``evsync``, read back; None when there is none."""
    meta = bag / 'metadata.yaml'
    if not meta.is_file():
        return None
    try:
        info = YAML(typ='safe').load(meta.read_text())['rosbag2_bagfile_information']
        text = (info.get('custom_data') or {}).get(PROVENANCE_KEY)
    except (OSError, YAMLError, KeyError, TypeError, AttributeError) as exc:
        raise BagError(f'{meta}: cannot read its custom_data ({exc})') from exc
    if text is None:
        return None
    try:
        record = json.loads(text)
    except (ValueError, TypeError) as exc:
        raise BagError(f'{bag}: its evsync provenance is not JSON ({exc})') from exc
    return record if isinstance(record, dict) else None
