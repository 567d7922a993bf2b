"""What the node's log says of its cameras (issue 52): each state change once, as it happens, at its
level, with what a reader needs (offset and error, the reason, the jump); a summary line that adds
up; nothing when nothing changed."""

from __future__ import annotations

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine import State, Status
from evsync_ros.ros.logbook import Level, Seen, changes, summary
from evsync_ros.runtime.wire import PathCounters


def status(topic: str = '/cam1/events', state: State = State.ESTIMATING, *, jumps: int = 0, message: str = '',
           correction: ClockCorrection | None = None, uncertainty_ns: float | None = None) -> Status:
    return Status(topic=topic, state=state, correction=correction, prior_ns=None, cost=0.0, confidence=1.0,
                  windows_tried=0, windows_accepted=0, jumps=jumps, events=0, far_events=0, silent_ns=None,
                  window_ns=None, message=message, uncertainty_ns=uncertainty_ns)


def test_a_lock_is_said_once_with_its_offset_and_error():
    locked = status(state=State.LOCKED, correction=ClockCorrection(offset_ns=-3_244_818_123, skew_ppm=1.5),
                    uncertainty_ns=253_000)
    lines, seen = changes(locked, Seen(State.ESTIMATING), reference=False)
    assert lines == [(Level.INFO, '/cam1/events: locked, offset -3244.818 ms +- 0.253 ms, skew +1.50 ppm')]
    assert changes(locked, seen, reference=False)[0] == []  # still locked: nothing more
    paper = status(state=State.LOCKED, correction=ClockCorrection(offset_ns=2_000_000))
    assert changes(paper, None, reference=False)[0] == [(Level.INFO, '/cam1/events: locked, offset +2.000 ms '
                                                                     'error unknown')]


def test_a_loss_and_a_clock_jump_are_warnings_with_their_reasons():
    lost = status(state=State.LOST, message='silent for 2.1 s; keeping the last correction')
    assert changes(lost, Seen(State.LOCKED), reference=False)[0] == [
        (Level.WARN, '/cam1/events: lost: silent for 2.1 s; keeping the last correction')]
    jumped = status(state=State.ESTIMATING, jumps=1, message='clock jump of +5.000 s in arrival lag; re-acquiring')
    lines, seen = changes(jumped, Seen(State.LOCKED), reference=False)
    assert lines == [(Level.WARN, '/cam1/events: clock jump (1 so far): clock jump of +5.000 s in arrival lag; '
                                  're-acquiring'),
                     (Level.INFO, '/cam1/events: estimating: clock jump of +5.000 s in arrival lag; re-acquiring')]
    assert seen == Seen(State.ESTIMATING, 1)
    assert changes(jumped, seen, reference=False)[0] == []


def test_the_reference_is_its_own_timeline_not_news_but_its_jump_is():
    ref = status('/cam0/events', State.LOCKED, correction=ClockCorrection(offset_ns=0), message='reference')
    assert changes(ref, None, reference=True)[0] == []
    jumped = status('/cam0/events', State.LOCKED, jumps=1, message='clock jump; every camera re-acquires')
    assert [level for level, _ in changes(jumped, Seen(State.LOCKED), reference=True)[0]] == [Level.WARN]


def test_the_summary_is_one_line_with_the_rates_since_the_last_one():
    statuses = [status('/cam0/events', State.LOCKED), status('/cam1/events', State.LOCKED,
                                                             correction=ClockCorrection(offset_ns=1_500_000),
                                                             uncertainty_ns=20_000),
                status('/cam2/events', State.LOST)]
    paths = {'/cam0/events': PathCounters(received=1000), '/cam1/events': PathCounters(received=500, malformed=2),
             '/cam2/events': PathCounters(received=0, messages_lost=3)}
    line, tally = summary(statuses, paths, None, 10_000_000_000, reference='/cam0/events')
    assert line == ('2 of 3 cameras locked: /cam0/events the reference; /cam1/events locked (offset +1.500 ms '
                    '+- 0.020 ms); /cam2/events lost; 3 messages lost upstream, 2 bad')
    later = {**paths, '/cam0/events': PathCounters(received=3000)}
    line, _ = summary(statuses, later, tally, 12_000_000_000, reference='/cam0/events')
    assert '/cam0/events the reference, 1000 msg/s;' in line and '/cam2/events lost, 0 msg/s;' in line
    assert '\n' not in line
