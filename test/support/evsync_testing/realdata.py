"""Where the real recordings are: test fixtures that never enter the repository.

``$EVSYNC_REAL_DATA`` when set, else ``../shared/data/real`` beside the repository these helpers are
in, else beside the current directory. ``../shared/data/real/README.md`` says what each recording
holds.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

ENV = 'EVSYNC_REAL_DATA'
SOURCE_TREE = Path(__file__).resolve().parents[3]
"""The repository root (test/support/evsync_testing/ is in it): these helpers are never installed."""


def real_data_dir() -> Path:
    """The folder of the real recordings (it may not exist: ``missing`` says why)."""
    env = os.environ.get(ENV)
    if env:
        return Path(env)
    for root in (SOURCE_TREE, Path.cwd()):
        candidate = root.parent / 'shared' / 'data' / 'real'
        if candidate.is_dir():
            return candidate
    return SOURCE_TREE.parent / 'shared' / 'data' / 'real'


def missing(path: Path, *names: str) -> str | None:
    """Why the recordings ``names`` (folders under ``path``) cannot be used, or None when they can."""
    absent = [n for n in names if not (path / n).is_dir()]
    if not absent:
        return None
    return (f'real recordings {", ".join(absent)} not found at {path} (put shared/ beside the repository '
            f'or set {ENV})')


def read_events(bag: Path) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Every event topic's events of a real recording: (t int64 ns, x, y, polarity), in bag order,
    decoded through the adapters as the bag tools decode them."""
    from evsync_ros.bag.reader import BagReader
    from msg_adapters.registry import decoder_for, is_event_type

    parts: dict[str, list[tuple[np.ndarray, ...]]] = {}
    with BagReader(bag) as reader:
        decoders = {c.topic: decoder_for(c.msgtype) for c in reader.connections if is_event_type(c.msgtype)}
        for conn, _, raw in reader.messages(list(decoders)):
            _, ev = decoders[conn.topic].decode(raw, xyp=True)
            assert ev.x is not None and ev.y is not None and ev.p is not None
            parts.setdefault(conn.topic, []).append((ev.t, ev.x, ev.y, ev.p))
    return {topic: (np.concatenate([c[0] for c in chunks]), np.concatenate([c[1] for c in chunks]),
                    np.concatenate([c[2] for c in chunks]), np.concatenate([c[3] for c in chunks]))
            for topic, chunks in parts.items()}
