"""One recording through the three paths a user runs, and whether they decide alike (issue 37).

A recording as a host records it (each message's record time its arrival on the host: what
``evsync_testing.virtualbag`` and ``evsync_ros.sim.simbag`` write) goes through:

* ``Route.ARRAYS``: the array API, ``read_event_arrivals`` then ``estimate_times`` with each event's
  arrival time (its record time) and each camera's model error, as ``estimate_bag`` has them;
* ``Route.CLI``: ``evsync estimate BAG --reference R --json``, the venv's command in a process of its
  own, as a user runs it;
* ``Route.NODE``: ``evsync_node`` in a process of its own with only ``topics``, ``types`` (the bag's
  message types) and ``reference`` set, fed by ``evsync play BAG`` at 1x over real DDS (loopback, a
  domain of its own), its decisions read from what it publishes: /diagnostics (state, line,
  standard errors, reason, messages in), /evsync/offsets and the status topics.

Each gives per camera a ``Verdict``: accepted (the node: locked), the offset line, its standard
errors, the reason. Two routes agree on a camera when both accept it or neither does, and where both
do, their offsets at the middle of the camera's recording lie within 3 combined standard errors
(``disagreements``). The node's verdict on a camera is its last report within ``QUIET_AFTER_S`` of
the player sending that camera's last message (a camera that sees nothing sends nothing, and may
go quiet before the recording ends): once the node calls the stream silent, it has fitted the windows
the stream's end allows, as ``evsync estimate`` does at the recording's end, and a camera lost only
to that silence keeps its correction (its verdict stands).
"""

from __future__ import annotations

import enum
import json
import math
import os
import random
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from evsync_ros.bag.estimate import model_systematic_ns, read_event_arrivals, read_event_times
from evsync_ros.bag.reader import BagReader
from evsync_ros.core.engine.arrays import estimate_times
from evsync_ros.core.paper import PaperParams
from evsync_ros.core.results import Method
from evsync_ros.errors import EvsyncError
from evsync_ros.sim.simbag import error_ns
from evsync_testing.listen import Spinning, diagnostics_of, newest_matched, play_when_matched
from msg_adapters.registry import is_event_type

BIN = Path(sys.executable).parent
"""Where the venv's ``evsync`` and ``evsync_node`` are."""
SE_LIMIT = 3.0
"""Two offsets agree within this many of their combined standard errors."""
WRONG_NS = 5_000_000
WRONG_SE = 5.0
"""The benchmarks' wrong answer: accepted and more than 5 ms, or more than 5 standard errors, off."""
QUIET_AFTER_S = 5.0
"""The node's verdict: its last report within this of the player's last message (past its
``silence_s``, 2 s by default, a step and a report later, each 1 s by default)."""


class Route(enum.Enum):
    ARRAYS = 'arrays'
    CLI = 'cli'
    NODE = 'node'


@dataclass(frozen=True)
class Verdict:
    """What one route decided of one camera."""

    topic: str
    accepted: bool
    """Accepted (offline) or locked (the node)."""
    offset_ns: int | None
    """The offset line at ``anchor_ns`` (None: no estimate, not even a best guess)."""
    skew_ppm: float = 0.0
    anchor_ns: int = 0
    se_ns: float | None = None
    """The offset's standard error at the anchor (None: none stated)."""
    skew_se_ppm: float | None = None
    reason: str = ''
    window_ns: tuple[int, int] | None = None
    """The span of the reference's timeline the estimate comes from (None: not said)."""

    def estimate(self) -> dict[str, Any]:
        """The line in the ``evsync estimate`` contract's form."""
        return {'offset_ns': self.offset_ns or 0, 'skew_ppm': self.skew_ppm, 'anchor_ns': self.anchor_ns}

    def offset_at(self, t_ns: int) -> float:
        """The offset the line gives at camera time ``t_ns`` (NaN: no estimate)."""
        if self.offset_ns is None:
            return math.nan
        return self.offset_ns + self.skew_ppm * 1e-6 * (t_ns - self.anchor_ns)

    def se_at(self, t_ns: int) -> float:
        """The offset's standard error at camera time ``t_ns``, the skew's over the distance from the
        anchor included (NaN: none stated)."""
        if self.se_ns is None:
            return math.nan
        return math.hypot(self.se_ns, (self.skew_se_ppm or 0.0) * 1e-6 * (t_ns - self.anchor_ns))

    def error_ns(self, truth: Mapping[str, Any], t_ns: int) -> float:
        """How far from the truth (contract form) the line puts camera time ``t_ns`` (NaN: no estimate)."""
        return math.nan if self.offset_ns is None else float(error_ns(self.estimate(), truth, t_ns))

    @classmethod
    def from_contract(cls, cam: Mapping[str, Any]) -> Verdict:
        """From a camera of the ``evsync estimate --json`` contract."""
        return cls(topic=cam['topic'], accepted=bool(cam['accepted']), offset_ns=int(cam['offset_ns']),
                   skew_ppm=float(cam['skew_ppm']), anchor_ns=int(cam['anchor_ns']),
                   se_ns=cam.get('uncertainty_ns'), skew_se_ppm=cam.get('skew_uncertainty_ppm'),
                   reason='' if cam['accepted'] else str(cam.get('reason', '')),
                   window_ns=(int(cam['window_ns'][0]), int(cam['window_ns'][1])) if 'window_ns' in cam else None)

    @classmethod
    def from_diagnostics(cls, topic: str, report: Mapping[str, str]) -> Verdict:
        """From a camera's status in /diagnostics (every value a string; empty where unknown): accepted
        where locked, or lost only to silence (its correction kept)."""
        state, message = report.get('state'), report.get('message', '')
        locked = state == 'locked' or (state == 'lost' and message.startswith('silent for'))

        def number(key: str) -> float | None:
            value = report.get(key, '')
            return float(value) if value not in ('', 'None', 'nan') else None
        offset = int(report['offset_ns']) if report.get('offset_ns', '').lstrip('-').isdigit() else number('offset_ns')
        start, end = report.get('window_start_ns', ''), report.get('window_end_ns', '')
        reason = '' if locked else f"{report.get('state', '?')}: {report.get('reason') or report.get('message', '')}"
        return cls(topic=topic, accepted=locked, offset_ns=None if offset is None else int(offset),
                   skew_ppm=number('skew_ppm') or 0.0, anchor_ns=int(number('anchor_ns') or 0),
                   se_ns=number('uncertainty_ns'), skew_se_ppm=number('skew_uncertainty_ppm'), reason=reason,
                   window_ns=(int(start), int(end)) if start and end else None)


def wrong(accepted: bool, error_ns: float | None, se_ns: float | None, *, within_se: float = WRONG_SE) -> bool:
    """Whether an answer is wrong: accepted and more than ``WRONG_NS``, or more than ``within_se``
    standard errors (when one is stated), from the truth."""
    if not accepted or error_ns is None or math.isnan(error_ns):
        return False
    off = abs(error_ns)
    stated = se_ns is not None and not math.isnan(se_ns) and se_ns > 0
    return off > WRONG_NS or (stated and off > within_se * se_ns)


def wrong_answers(verdicts: Mapping[str, Verdict], truth: Mapping[str, Any], *, middles: Mapping[str, int]
                  ) -> list[str]:
    """The verdicts that are ``wrong`` against ``truth`` (the contract's form, with ``cameras``), one
    line each, judged at the middle of each camera's recording."""
    true = {c['topic']: c for c in truth['cameras']}
    out = []
    for topic, v in sorted(verdicts.items()):
        mid = middles[topic]
        err, se = v.error_ns(true[topic], mid), v.se_at(mid)
        if wrong(v.accepted, err, se):
            out.append(f'{topic}: accepted {err / 1e6:+.3f} ms from the truth, standard error {se / 1e6:.3f} ms')
    return out


def disagreements(a: Mapping[str, Verdict], b: Mapping[str, Verdict], *, middles: Mapping[str, int],
                  names: tuple[str, str] = ('a', 'b'), resolution_ns: float = 0.0) -> list[str]:
    """What two routes' verdicts disagree on, one line per camera (empty: they agree): one accepts a
    camera the other does not, or both do and their offsets at the middle of the camera's recording
    are more than ``SE_LIMIT`` combined standard errors, and more than ``resolution_ns``, apart
    (``differ``; the paper's method states no error: its resolution is its bin, tau)."""
    out = []
    for topic in sorted(set(a) | set(b)):
        va, vb = a.get(topic), b.get(topic)
        if va is None or vb is None:
            out.append(f'{topic}: only {names[0] if vb is None else names[1]} gives a verdict')
            continue
        mid = middles[topic]
        found = differ((va.accepted, va.offset_at(mid), va.se_at(mid), va.reason),
                       (vb.accepted, vb.offset_at(mid), vb.se_at(mid), vb.reason), names=names,
                       resolution_ns=resolution_ns)
        if found:
            out.append(f'{topic}: {found}')
    return out


def differ(a: tuple[bool, float, float, str], b: tuple[bool, float, float, str], *,
           names: tuple[str, str] = ('a', 'b'), resolution_ns: float = 0.0) -> str:
    """Whether two verdicts of one camera, each (accepted, offset, standard error, reason) at one
    instant, decide differently ('' when alike): one accepts and the other does not, or both accept
    and the offsets are more than ``SE_LIMIT`` combined standard errors apart (a missing standard
    error counts as 0). The offsets may be errors against one truth instead: only their difference
    counts."""
    if a[0] != b[0]:
        yes, no = (names[0], b) if a[0] else (names[1], a)
        return f'accepted by {yes} only; the other says {no[3]!r}'
    if not a[0]:
        return ''
    apart = a[1] - b[1]
    se = math.hypot(np.nan_to_num(a[2]), np.nan_to_num(b[2]))
    if abs(apart) <= max(SE_LIMIT * se, resolution_ns):
        return ''
    return (f'offsets {apart / 1e6:+.3f} ms apart, {abs(apart) / se if se else math.inf:.1f} combined standard '
            f'errors ({se / 1e6:.3f} ms)')


# -- the offline routes ------------------------------------------------------------------------------

def event_times(bag: Path) -> dict[str, np.ndarray]:
    """Every event topic's times (sorted int64 ns), as the array API reads them."""
    times, _ = read_event_times(bag)
    return times


def middles_of(times: Mapping[str, np.ndarray]) -> dict[str, int]:
    """The middle (median) of each camera's event times: where the routes are compared."""
    return {t: int(np.median(arr)) for t, arr in times.items() if arr.size}


def through_arrays(bag: Path, *, reference: str, method: Method = Method.REFINED) -> dict[str, Verdict]:
    """The array API on a recording's events held in memory, each with its arrival time (its record
    time), and each camera's model error (``model_systematic_ns``): the same evidence ``estimate_bag``
    has."""
    times, arrivals, reports = read_event_arrivals(bag)
    rig = estimate_times(times, reference=reference, consistency=False, arrivals_ns=arrivals, method=method,
                         systematic_ns=model_systematic_ns(reports, reference=reference))
    return {c.topic: Verdict.from_contract(c.as_json()) for c in rig.cameras if c.topic != reference}


def through_cli(bag: Path, *, reference: str, method: Method = Method.REFINED) -> dict[str, Verdict]:
    """``evsync estimate BAG --reference R --json``, as a user runs it."""
    done = subprocess.run([str(BIN / 'evsync'), 'estimate', str(bag), '--reference', reference, '--json',
                           '--method', method.value],
                          check=False, capture_output=True, text=True, timeout=1800)
    if done.returncode not in (0, 1):  # 1: a camera not accepted, said in the JSON
        raise EvsyncError(f'evsync estimate {bag} exited {done.returncode}: {done.stderr.strip()}')
    doc = json.loads(done.stdout)
    return {c['topic']: Verdict.from_contract(c) for c in doc['cameras'] if c['topic'] != reference}


# -- the node ----------------------------------------------------------------------------------------

@dataclass
class NodeRun:
    """What the node published while a bag was played into it, and its verdict per camera."""

    verdicts: dict[str, Verdict]
    sent: dict[str, int]
    """Messages ``evsync play`` sent per topic."""
    received: dict[str, int]
    """Messages the node took per topic (``messages_in`` of its verdict's report)."""
    reports: list[tuple[float, dict[str, dict[str, str]]]] = field(repr=False)
    """Every /diagnostics message: (seconds after the player started, {hardware_id: values})."""
    offsets: dict[str, tuple[int, int]] = field(default_factory=dict)
    """The last /evsync/offsets per camera by the verdict's time: (rig time, own time)."""
    status: dict[str, dict[str, float]] = field(default_factory=dict)
    """The last value of each status topic per camera by the verdict's time (offset_ms,
    offset_std_ms, state, ...)."""
    log: str = field(default='', repr=False)

    def states(self, topic: str) -> list[str]:
        """The camera's state in each report, in order."""
        return [r[topic]['state'] for _, r in self.reports if topic in r]


STATUS_QUANTITIES = ('offset_ms', 'offset_std_ms', 'skew_ppm', 'state')


class _Listener(Spinning):
    """/diagnostics, /evsync/offsets and the status topics, taken by a thread of this process."""

    def __init__(self, topics: Sequence[str], domain_id: int) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import TimeReference
        from std_msgs.msg import Float64
        super().__init__('evsync_paths_listener', domain_id=domain_id)
        self.start_s = time.monotonic()
        self.reports: list[tuple[float, dict[str, dict[str, str]]]] = []
        self.offsets: list[tuple[float, str, int, int]] = []
        self.status: list[tuple[float, str, str, float]] = []
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._diagnostics, 100)
        self.node.create_subscription(TimeReference, '/evsync/offsets', self._offset, 100)
        for topic in topics:
            for quantity in STATUS_QUANTITIES:
                self.node.create_subscription(Float64, f'/evsync/status{topic}/{quantity}',
                                              self._status(topic, quantity), 100)
        self.start()

    def _diagnostics(self, msg: Any) -> None:
        per = {hw: {k: str(v) for k, v in values.items()} for hw, values in diagnostics_of(msg).items()}
        self.reports.append((time.monotonic() - self.start_s, per))

    def _offset(self, msg: Any) -> None:
        self.offsets.append((time.monotonic() - self.start_s, msg.source,
                             msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
                             msg.time_ref.sec * 1_000_000_000 + msg.time_ref.nanosec))

    def _status(self, topic: str, quantity: str) -> Any:
        def take(msg: Any) -> None:
            self.status.append((time.monotonic() - self.start_s, topic, quantity, float(msg.data)))
        return take


def bag_topics(bag: Path) -> dict[str, str]:
    """The bag's event topics and their message types, in the bag's order."""
    with BagReader(bag) as reader:
        return {c.topic: c.msgtype for c in reader.connections if is_event_type(c.msgtype)}


def last_messages(bag: Path, topics: Sequence[str]) -> dict[str, float]:
    """How long before the bag's last message each topic sent its own last one (s): a camera that
    sees nothing sends nothing (dvs arrays), and goes quiet before the recording ends."""
    last: dict[str, int] = {}
    end = 0
    with BagReader(bag) as reader:
        for conn, stamp, _ in reader.messages(list(topics)):
            last[conn.topic] = stamp
            end = max(end, stamp)
    return {t: (end - last[t]) / 1e9 for t in last}


def through_node(bag: Path, *, reference: str, domain_id: int | None = None, work: Path | None = None,
                 extra: Mapping[str, Any] | None = None, rate: float = 1.0) -> NodeRun:
    """``evsync_node`` with only topics, types and reference set (and ``extra``, parameters a test
    wants besides), fed by ``evsync play BAG`` at ``rate`` (1x); takes about as long as the recording.
    ``domain_id``: the DDS domain (default: a random one, so that runs side by side do not meet)."""
    domain = domain_id if domain_id is not None else random.SystemRandom().randint(1, 200)
    env = {**os.environ, 'ROS_DOMAIN_ID': str(domain), 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    kinds = bag_topics(bag)
    topics = list(kinds)
    params = {'topics': topics, 'types': [kinds[t] for t in topics], 'reference': reference, **(extra or {})}
    with tempfile.TemporaryDirectory(prefix='evsync-paths-', dir=work) as tmp:
        params_file = Path(tmp) / 'params.yaml'
        params_file.write_text(json.dumps({'evsync': {'ros__parameters': params}}))  # JSON is YAML
        listener = _Listener(topics, domain)
        node = subprocess.Popen([str(BIN / 'evsync_node'), '--ros-args', '--params-file', str(params_file)],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
        try:
            deadline = time.monotonic() + 60
            while not listener.node.count_publishers('/diagnostics'):
                if time.monotonic() > deadline or node.poll() is not None:
                    raise EvsyncError(f'evsync_node did not come up for {bag}')
                time.sleep(0.1)
            listener.start_s = time.monotonic()
            since = time.monotonic() - listener.start_s
            try:
                player = play_when_matched(
                    listener, [str(BIN / 'evsync'), 'play', str(bag), '--rate', str(rate), '--wait-subscribers', '1'],
                    lambda: newest_matched(listener.reports, since, topics, outputs=False),
                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
            except (RuntimeError, TimeoutError) as exc:
                raise EvsyncError(f'{bag}: {exc}') from exc
            out, err = player.communicate(timeout=3600)
            if player.returncode != 0:
                raise EvsyncError(f'evsync play {bag} exited {player.returncode}: {err.strip()}')
            last_sent = time.monotonic() - listener.start_s - 0.5  # play waits 0.5 s after its last message
            time.sleep(QUIET_AFTER_S + 0.5)
        finally:
            node.terminate()
            try:
                log = node.communicate(timeout=30)[0]
            except subprocess.TimeoutExpired:
                node.kill()
                log = node.communicate()[0]
            listener.close()
    sent = {line.split(': ')[0]: int(line.split(': ')[1].split()[0])
            for line in out.splitlines() if line.endswith(' messages')}
    before_end = {t: s / rate for t, s in last_messages(bag, topics).items()}  # (wall seconds at ``rate``)
    final = _final_reports(listener.reports, topics,
                           until_s={t: last_sent - before_end.get(t, 0.0) + QUIET_AFTER_S for t in topics})
    verdicts = {t: Verdict.from_diagnostics(t, final[t]) for t in topics if t != reference and t in final}
    missing = [t for t in topics if t not in final]
    if missing:
        raise EvsyncError(f'evsync_node reported nothing of {", ".join(missing)} while {bag} played:\n{log}')
    received = {t: int(final[t].get('messages_in', 0)) for t in topics}
    until = {t: last_sent - before_end.get(t, 0.0) + QUIET_AFTER_S for t in topics}
    offsets = {source: (rig, own) for at, source, rig, own in listener.offsets if at <= until.get(source, 0.0)}
    status: dict[str, dict[str, float]] = {t: {} for t in topics}
    for at, topic, quantity, value in listener.status:
        if at <= until[topic]:
            status[topic][quantity] = value
    return NodeRun(verdicts=verdicts, sent=sent, received=received, reports=listener.reports, offsets=offsets,
                   status=status, log=log)


def _final_reports(reports: Iterable[tuple[float, dict[str, dict[str, str]]]], topics: Sequence[str], *,
                   until_s: Mapping[str, float]) -> dict[str, dict[str, str]]:
    """Each camera's last report received before its ``until_s``."""
    final: dict[str, dict[str, str]] = {}
    for at, per in reports:
        for topic in topics:
            if topic in per and at <= until_s[topic]:
                final[topic] = per[topic]
    return final


# -- all of them -------------------------------------------------------------------------------------

@dataclass
class Outcome:
    """One recording through the routes asked for."""

    bag: Path
    reference: str
    middles: dict[str, int]
    verdicts: dict[Route, dict[str, Verdict]]
    node: NodeRun | None = None
    method: Method = Method.REFINED

    def disagreements(self, a: Route, b: Route) -> list[str]:
        resolution = PaperParams().tau_ns if self.method is Method.PAPER else 0
        return disagreements(self.verdicts[a], self.verdicts[b], middles=self.middles, names=(a.value, b.value),
                             resolution_ns=resolution)

    def table(self, truth: Mapping[str, Any] | None = None) -> str:
        """One line per camera and route: accepted, offset at the middle, standard error there, and
        the error against ``truth`` (the contract's form, with ``cameras``) when given, or the reason."""
        true = {c['topic']: c for c in (truth or {}).get('cameras', ())}
        lines = [f'{"camera":<22} {"route":<6} {"acc":>3} {"offset at middle s":>20} {"se ms":>7} {"err ms":>8}  '
                 'reason']
        for topic in sorted(self.middles):
            if topic == self.reference:
                continue
            mid = self.middles[topic]
            for route, per in self.verdicts.items():
                v = per.get(topic)
                if v is None:
                    continue
                err = v.error_ns(true[topic], mid) / 1e6 if topic in true else math.nan
                lines.append(f'{topic:<22} {route.value:<6} {"yes" if v.accepted else "no":>3} '
                             f'{v.offset_at(mid) / 1e9:>+20.9f} {v.se_at(mid) / 1e6:>7.3f} {err:>+8.3f}  '
                             f'{v.reason[:90]}')
        return '\n'.join(lines)


def run(bag: Path, *, reference: str, routes: Sequence[Route] = tuple(Route), domain_id: int | None = None,
        times: Mapping[str, np.ndarray] | None = None, method: Method = Method.REFINED) -> Outcome:
    """``bag`` through each of ``routes`` by ``method`` with its default parameters (``times``: its
    event times, when read already)."""
    times = times if times is not None else event_times(bag)
    verdicts: dict[Route, dict[str, Verdict]] = {}
    node = None
    for route in routes:
        if route is Route.ARRAYS:
            verdicts[route] = through_arrays(bag, reference=reference, method=method)
        elif route is Route.CLI:
            verdicts[route] = through_cli(bag, reference=reference, method=method)
        else:
            node = through_node(bag, reference=reference, domain_id=domain_id, extra={'method': method.value})
            verdicts[route] = node.verdicts
    return Outcome(bag=bag, reference=reference, middles=middles_of(times), verdicts=verdicts, node=node,
                   method=method)


def far_epochs(preset: str = 'bursty', *, seed: int = 0, duration_s: float = 20.0) -> Any:
    """A simulator preset's three cameras with clocks on far-apart epochs: the reference (evt3) on
    the host's epoch, the second (dvs) on a sensor clock 5 s since boot, the third (dvs: its times
    are its clock, where evt3's are anchored by header stamps) 1000 s behind the reference's."""
    from dataclasses import replace

    from evsync_ros.sim import pixelsim
    rig = pixelsim.preset(preset, seed=seed, duration_s=duration_s)
    ref, second, third = rig.cameras[:3]
    return replace(rig, cameras=(
        ref,
        replace(second, encoding='dvs', clock_at_start_ns=5_000_000_000 + second.start_ns),
        replace(third, encoding='dvs',
                clock_at_start_ns=ref.clock_at_start_ns - ref.start_ns + third.start_ns - 1_000_000_000_000)))
