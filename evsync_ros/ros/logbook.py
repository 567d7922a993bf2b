"""What the node's log says of the cameras: each one's state changes as they happen (locked, with
its offset and error, at INFO; lost with the reason, and a clock jump, at WARN), and a one-line
summary every ``log_summary_s``. Never a line per message. Pure functions of the estimate's
``Status`` and what was seen before."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from evsync_ros.core.engine import State, Status
from evsync_ros.runtime.wire import PathCounters

__all__ = ['Level', 'Seen', 'Tally', 'changes', 'summary']


class Level(Enum):
    INFO = 'info'
    WARN = 'warn'


@dataclass(frozen=True)
class Seen:
    """A camera as the log last said it."""

    state: State
    jumps: int = 0


@dataclass(frozen=True)
class Tally:
    """What the previous summary counted, for the rates since."""

    at_ns: int
    messages_in: dict[str, int]


def offset_text(s: Status) -> str:
    """A correction's offset and its error, as the log says them."""
    c = s.correction
    if c is None:
        return 'no correction'
    error = 'error unknown' if s.uncertainty_ns is None else f'+- {s.uncertainty_ns / 1e6:.3f} ms'
    skew = f', skew {c.skew_ppm:+.2f} ppm' if c.skew_ppm else ''
    return f'offset {c.offset_ns / 1e6:+.3f} ms {error}{skew}'


def changes(s: Status, before: Seen | None, *, reference: bool) -> tuple[list[tuple[Level, str]], Seen]:
    """What to log of camera ``s.topic`` since it was ``before`` (None: nothing said yet), and what
    is seen now. The reference's own lock is its timeline, not news."""
    lines: list[tuple[Level, str]] = []
    jumps = before.jumps if before is not None else 0
    if s.jumps > jumps:
        lines.append((Level.WARN, f'{s.topic}: clock jump ({s.jumps} so far): {s.message}'))
    was = before.state if before is not None else None
    if s.state is not was:
        if s.state is State.LOCKED and not reference:
            lines.append((Level.INFO, f'{s.topic}: locked, {offset_text(s)}'))
        elif s.state is State.LOST:
            lines.append((Level.WARN, f'{s.topic}: lost: {s.message}'))
        elif was is State.LOCKED or was is State.LOST:
            lines.append((Level.INFO, f'{s.topic}: {s.state.value}: {s.message}'))
    return lines, Seen(s.state, s.jumps)


def summary(statuses: list[Status], paths: dict[str, PathCounters], before: Tally | None, now_ns: int,
            *, reference: str) -> tuple[str, Tally]:
    """One line for every camera: its state (offset and error once locked) and messages in per
    second since the previous summary, then what was lost or bad in all; and what it counted."""
    seconds = (now_ns - before.at_ns) / 1e9 if before is not None and now_ns > before.at_ns else 0.0
    parts = []
    for s in statuses:
        path = paths[s.topic]
        if s.topic == reference:
            said = 'the reference'
        else:
            said = s.state.value + (f' ({offset_text(s)})' if s.state is State.LOCKED else '')
        if seconds:
            rate = (path.received - before.messages_in.get(s.topic, 0)) / seconds  # type: ignore[union-attr]
            said += f', {rate:.0f} msg/s'
        parts.append(f'{s.topic} {said}')
    locked = sum(s.state is State.LOCKED for s in statuses)
    lost = sum(p.messages_lost for p in paths.values())
    bad = sum(p.malformed + p.unrestamped for p in paths.values())
    line = (f'{locked} of {len(statuses)} cameras locked: {"; ".join(parts)}; '
            f'{lost} messages lost upstream, {bad} bad')
    return line, Tally(now_ns, {t: p.received for t, p in paths.items()})
