"""Operating a running rig: saved offsets that seed a restarted node, and the node's services to
save them, to re-acquire and to freeze. The file is the ``evsync estimate --json``
contract (``core.results``), so an estimate of a bag seeds the node and a saved file restamps a bag."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from rclpy.node import Node
from std_srvs.srv import SetBool, Trigger

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


class Services:
    """The node's services (std_srvs, under its name): ``~/save_offsets`` writes the corrections in
    force to ``offsets_file``, ``~/freeze`` keeps them (a take), ``~/reacquire`` forgets them."""

    def __init__(self, node: Node, sync: Engine, offsets_file: str) -> None:
        self.sync = sync
        self.offsets_file = offsets_file
        self.logger = node.get_logger()
        node.create_service(Trigger, '~/save_offsets', self._on_save_offsets)
        node.create_service(Trigger, '~/reacquire', self._on_reacquire)
        node.create_service(SetBool, '~/freeze', self._on_freeze)

    def seed(self) -> None:
        """Every camera of ``offsets_file`` seeded (ParameterError, naming the file, when it is not
        the contract or is another reference's)."""
        path = self.offsets_file
        if not path:
            return
        seeded = seed_from_file(self.sync, path)
        if seeded is None:
            self.logger.warning(f'offsets_file {path}: not there yet; estimating from scratch (~/save_offsets '
                                'writes it)')
        else:
            self.logger.info(f'offsets_file {path}: seeded {", ".join(seeded) or "no camera"}')

    def _on_save_offsets(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        path = self.offsets_file
        if not path:
            response.success, response.message = False, 'offsets_file is not set: nowhere to save'
            return response
        try:
            n = save_offsets(self.sync, path)
        except OSError as exc:
            response.success, response.message = False, f'{path}: {exc}'
            return response
        response.success, response.message = True, f'{n} cameras and the reference saved to {path}'
        self.logger.info(response.message)
        return response

    def _on_reacquire(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.sync.reacquire()
        response.success, response.message = True, 'every camera re-estimates from the events held'
        self.logger.info(response.message)
        return response

    def _on_freeze(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        self.sync.freeze(bool(request.data))
        response.success = True
        response.message = ('frozen: the corrections in force stay until ~/freeze false or ~/reacquire'
                            if request.data else 'estimating again')
        self.logger.info(response.message)
        return response
