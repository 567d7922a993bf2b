"""A node of a context of its own, spun by a thread of this process: what the tests and the path
runner listen to the node's outputs with over real DDS (rclpy imported when one is made)."""

from __future__ import annotations

import subprocess
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any

__all__ = ['Spinning', 'call_service', 'diagnostics_of', 'matched', 'newest_matched', 'play_when_matched']

RESUME = '/evsync_player/resume'
"""The service of a player started with ``--start-paused`` that starts its playing."""


class Spinning:
    """``rclpy`` initialised in a context of its own (``domain_id``: a DDS domain of its own, else
    the environment's), one node in it; ``start`` spins it in a thread, ``close`` ends both."""

    def __init__(self, name: str, *, domain_id: int | None = None) -> None:
        import rclpy
        self.context = rclpy.context.Context()
        if domain_id is None:
            rclpy.init(context=self.context)
        else:
            rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._run = False
        self.thread = threading.Thread(target=self._spin, daemon=True)

    def start(self) -> None:
        """Spin the node from now on (its subscriptions made)."""
        self._run = True
        self.thread.start()

    def _spin(self) -> None:
        while self._run:
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        import rclpy
        self._run = False
        if self.thread.is_alive():
            self.thread.join(timeout=5)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def diagnostics_of(msg: Any) -> dict[str, dict[str, Any]]:
    """A DiagnosticArray as {hardware_id: {'level': int, 'message': str, key: value, ...}}."""
    per = {}
    for s in msg.status:
        level = int.from_bytes(s.level, 'little') if isinstance(s.level, bytes) else int(s.level)
        per[s.hardware_id] = {'level': level, 'message': s.message, **{kv.key: kv.value for kv in s.values}}
    return per


def matched(report: dict[str, dict[str, Any]], topics: Iterable[str], *, outputs: bool = True) -> bool:
    """Whether a node's /diagnostics report (``diagnostics_of``) says each of ``topics`` takes its input
    from a publisher it has matched, and (``outputs``) has a subscriber matched on its output."""
    for topic in topics:
        values = report.get(topic, {})
        pubs, subs = str(values.get('publishers', '')), str(values.get('subscribers', ''))
        if not (pubs.isdigit() and int(pubs) >= 1) or (outputs and subs.isdigit() and int(subs) < 1):
            return False
    return True


def newest_matched(reports: Sequence[tuple[float, dict[str, dict[str, Any]]]], since: float, topics: Iterable[str],
                   *, outputs: bool = True) -> bool:
    """Whether the newest of ``reports`` ((when, ``diagnostics_of`` report), in the order they came)
    came after ``since`` and is ``matched``."""
    return bool(reports) and reports[-1][0] > since and matched(reports[-1][1], topics, outputs=outputs)


SETTLE_S = 0.5
"""After a service is offered, how long its reply path is given to match this client: ``wait_for_service``
sees the server's request reader, and a reply its writer sends before it matches the client is lost
(CI saw /evsync_player/resume unanswered for 60 s once)."""
RETRY_S = 5.0
"""A request unanswered this long is sent again (the services called so: idempotent)."""


def call_service(spinning: Spinning, srv_type: Any, name: str, request: Any, *, timeout_s: float = 20.0) -> Any:
    """Call service ``name`` from ``spinning``'s node (its thread spins), and wait for the answer,
    asking again every ``RETRY_S`` (only for services that may be called twice); TimeoutError when it
    is not offered or does not answer within ``timeout_s``."""
    client = spinning.node.create_client(srv_type, name)
    try:
        if not client.wait_for_service(timeout_sec=timeout_s):
            raise TimeoutError(f'{name} not offered')
        time.sleep(SETTLE_S)
        deadline = time.monotonic() + timeout_s
        while True:
            future, again = client.call_async(request), time.monotonic() + RETRY_S
            while not future.done() and time.monotonic() < min(again, deadline):
                time.sleep(0.02)
            if future.done():
                return future.result()
            if time.monotonic() >= deadline:
                raise TimeoutError(f'{name}: no response')
    finally:
        spinning.node.destroy_client(client)


def play_when_matched(spinning: Spinning, command: Sequence[str], is_matched: Callable[[], bool], *,
                      timeout_s: float = 60.0, held_s: float | None = None, **popen: Any) -> subprocess.Popen[str]:
    """Start ``command`` (``evsync play BAG ...``) paused, and resume it once ``is_matched()`` (the
    node's report, newer than the player: ``matched``). The player sees its subscribers before they
    see it; a message it sent in between would be lost to them, and a test would count it lost.
    ``held_s``: a node on sim time reports once while the paused player holds /clock, perhaps
    before it has matched the player: resume anyway after that long (the player's own wait for its
    subscribers is then all there is)."""
    from std_srvs.srv import Trigger
    player = subprocess.Popen([*command[:2], '--start-paused', *command[2:]], text=True, **popen)
    try:
        started = time.monotonic()
        deadline = started + timeout_s
        while not is_matched() and (held_s is None or time.monotonic() < started + held_s):
            if player.poll() is not None:
                raise RuntimeError(f'{" ".join(command)} exited {player.returncode} before it played')
            if time.monotonic() > deadline:
                raise TimeoutError(f'the node did not match the player of {" ".join(command)} in {timeout_s:g} s')
            time.sleep(0.05)
        call_service(spinning, Trigger, RESUME, Trigger.Request(), timeout_s=timeout_s)
    except BaseException:
        player.kill()
        player.wait()
        raise
    return player
