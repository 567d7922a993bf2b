"""Operating a running rig (issue 24): saved offsets that seed a restarted node, and the node's
services to save them, to re-acquire and to freeze. The file is the ``evsync estimate --json``
contract (``core.results``), so an estimate of a bag seeds the node and a saved file restamps a bag."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from evsync_ros.core.engine import Engine
from evsync_ros.core.results import RigFit, load_rig
from evsync_ros.errors import ParameterError


def seed_from_file(sync: Engine, path: str | Path) -> list[str] | None:
    """Seed every accepted camera of the file that is a camera of ``sync``'s rig; the topics seeded,
    or None when the file does not exist yet (a first start). ParameterError naming the file when it
    is not the contract, or is for another reference."""
    path = Path(path).expanduser()
    if not path.exists():
        return None
    rig = load_rig(path)
    if rig.reference != sync.reference:
        raise ParameterError(f'offsets_file {path}: its reference is {rig.reference}, this node\'s is '
                             f'{sync.reference}')
    seeded = []
    for cam in rig.cameras:
        if cam.topic != rig.reference and cam.accepted and cam.topic in sync.topics:
            sync.seed(cam)
            seeded.append(cam.topic)
    return seeded


def save_offsets(sync: Engine, path: str | Path) -> int:
    """Write the corrections in force (``Engine.saved``) to ``path`` in the contract, replacing it
    whole or not at all; how many cameras besides the reference it holds. OSError as the system says."""
    path = Path(path).expanduser()
    saved = sync.saved()
    rig = RigFit(reference=sync.reference, cameras=tuple(saved.values()))
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.partial', dir=path.parent)
    try:
        with os.fdopen(fd, 'w') as f:
            json.dump(rig.as_json(), f)
            f.write('\n')
        Path(tmp).replace(path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return len(saved) - 1
