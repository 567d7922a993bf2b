"""The storages a bag is kept in: a rosbag2's sqlite3 or mcap files, or a ROS 1 bag, named by an enum
that every module of ``bag`` dispatches on (``reader.PLUGINS``, the writer's choice of storage)."""

from __future__ import annotations

import contextlib
import enum
from pathlib import Path

from ruamel.yaml import YAML

from evsync_ros.bag import ros1
from evsync_ros.errors import BagError

__all__ = ['ROSBAG2', 'Storage', 'input_storage', 'output_storage']


class Storage(enum.StrEnum):
    """A bag's storage, by the name ``ros2 bag`` gives it (``ros1``: a ROS 1 ``.bag`` file)."""

    SQLITE3 = 'sqlite3'
    MCAP = 'mcap'
    ROS1 = 'ros1'

    @classmethod
    def of(cls, value: object, *, bag: object, among: tuple[Storage, ...] = ()) -> Storage:
        """``value`` as a storage (one of ``among``, default any), else BagError naming ``bag`` and
        the choices."""
        choices = among or tuple(cls)
        found = next((s for s in choices if s == value), None)
        if found is None:
            raise BagError(f'{bag}: storage must be one of {", ".join(choices)}, got {value!r}')
        return found

    @classmethod
    def of_file(cls, path: Path) -> Storage:
        """A rosbag2 storage file's storage, by its suffixes (``.db3.zstd``, compressed whole, too)."""
        return cls.MCAP if '.mcap' in path.suffixes else cls.SQLITE3


ROSBAG2 = (Storage.SQLITE3, Storage.MCAP)
"""The storages of a rosbag2."""
SUFFIXES = ('.mcap', '.db3')
"""A rosbag2 storage file's suffix."""


def input_storage(bag: str | Path) -> Storage:
    """A bag's storage: ROS 1 for a ROS 1 bag, else the rosbag2 storage its metadata.yaml names, else
    its storage files' (compressed whole, .db3.zstd, too); BagError when it has none."""
    p = Path(bag)
    if p.is_file() and ros1.is_ros1(p):
        return Storage.ROS1
    meta = p / 'metadata.yaml'
    if p.is_dir() and meta.is_file():
        with contextlib.suppress(Exception):  # unreadable metadata: the files say, and the reader will say why
            named = YAML(typ='safe').load(meta.read_text())['rosbag2_bagfile_information']['storage_identifier']
            if named in ROSBAG2:
                return Storage(named)
    files = [p] if p.is_file() else sorted(f for f in p.iterdir() if set(SUFFIXES) & set(f.suffixes))
    if not files:
        raise BagError(f'{bag}: no .mcap or .db3 storage file')
    return Storage.of_file(files[0])


def output_storage(bag: str | Path) -> Storage:
    """The rosbag2 storage an output of ``bag`` is written in by default: the input's (mcap, ROS 2's
    default, for a ROS 1 bag)."""
    found = input_storage(bag)
    return Storage.MCAP if found is Storage.ROS1 else found
