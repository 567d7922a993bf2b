"""evsync play (issue 24): each topic goes out with the QoS it was recorded with, as ros2 bag play
does, reliable where the bag recorded none; --reliable and --best-effort force one for all. Real
DDS on loopback: the player's publishers are seen as a subscriber sees them."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

rclpy = pytest.importorskip('rclpy', reason='rclpy is installed by ./dev setup')

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from evsync_ros.bag.writer import BagWriter, Compression, Layout  # noqa: E402
from evsync_testing.crafted import edit_mcap_channel  # noqa: E402

BIN = Path(sys.executable).parent
S = 1_000_000_000
NEVER = QosTime(0x7FFFFFFF, 0xFFFFFFFF)


def offered(reliability: QosReliability, durability: QosDurability, depth: int) -> Qos:
    return Qos(QosHistory.KEEP_LAST, depth, reliability, durability, NEVER, NEVER, QosLiveliness.AUTOMATIC, NEVER,
               False)


def bag_with_qos(path: Path) -> Path:
    """Three String topics over 3 s: /events recorded best effort (a driver's), /info transient local
    (a latched camera_info), /plain with no QoS recorded."""
    with BagWriter(path) as w:
        conns = {
            '/events': w.add_topic('/events', 'std_msgs/msg/String',
                                   offered_qos_profiles=[offered(QosReliability.BEST_EFFORT, QosDurability.VOLATILE,
                                                                 1000)]),
            '/info': w.add_topic('/info', 'std_msgs/msg/String',
                                 offered_qos_profiles=[offered(QosReliability.RELIABLE,
                                                               QosDurability.TRANSIENT_LOCAL, 1)]),
            '/plain': w.add_topic('/plain', 'std_msgs/msg/String'),
        }
        for k in range(4):
            for conn in conns.values():
                w.write(conn, 10 * S + k * S, serialize_message(String(data=str(k))))
    return path


def seen_qos(args: list[str], bag: Path) -> dict[str, tuple[ReliabilityPolicy, DurabilityPolicy]]:
    """The player's publishers' QoS per topic, as DDS shows them to a subscriber."""
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('play_qos_probe', context=context)
    anything = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)
    for topic in ('/events', '/info', '/plain'):
        node.create_subscription(String, topic, lambda _m: None, anything)
    player = subprocess.Popen([str(BIN / 'evsync'), 'play', str(bag), '--wait-subscribers', '1', *args],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seen: dict[str, tuple[ReliabilityPolicy, DurabilityPolicy]] = {}
    try:
        deadline = time.monotonic() + 20
        while len(seen) < 3 and time.monotonic() < deadline:
            for topic in ('/events', '/info', '/plain'):
                info = node.get_publishers_info_by_topic(topic)
                if info:
                    seen[topic] = (info[0].qos_profile.reliability, info[0].qos_profile.durability)
            time.sleep(0.05)
        out = player.communicate(timeout=30)[0]
    finally:
        player.kill()
        node.destroy_node()
        rclpy.shutdown(context=context)
    assert player.returncode == 0, out
    assert '/events: 4 messages' in out
    return seen


def test_each_topic_is_played_with_its_recorded_qos(tmp_path):
    seen = seen_qos([], bag_with_qos(tmp_path / 'bag'))
    assert seen == {'/events': (ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE),
                    '/info': (ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL),
                    '/plain': (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE)}


@pytest.mark.parametrize(('flag', 'reliability'), [('--reliable', ReliabilityPolicy.RELIABLE),
                                                   ('--best-effort', ReliabilityPolicy.BEST_EFFORT)])
def test_a_flag_forces_one_qos_for_every_topic(tmp_path, flag, reliability):
    seen = seen_qos([flag], bag_with_qos(tmp_path / 'bag'))
    assert {r for r, _ in seen.values()} == {reliability} and len(seen) == 3


# -- the options of ros2 bag play (issue 39) ---------------------------------------------------------

def string_bag(path: Path, topics: tuple[str, ...] = ('/a',), *, n: int = 20, step_s: float = 0.1,
               layout: Layout = Layout()) -> Path:
    """``n`` std_msgs/String per topic, ``step_s`` apart from 10 s, each saying its index."""
    with BagWriter(path, layout=layout) as w:
        conns = [w.add_topic(t, 'std_msgs/msg/String') for t in topics]
        for k in range(n):
            for conn in conns:
                w.write(conn, 10 * S + round(k * step_s * S), serialize_message(String(data=str(k))))
    return path


class Heard:
    """What a subscriber in this process hears of the player: each topic's messages (their index) and
    /clock, in the order they came."""

    def __init__(self, topics: tuple[str, ...], *, clock: bool = False) -> None:
        from rosgraph_msgs.msg import Clock

        self.context = rclpy.context.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('play_probe', context=self.context)
        self.got: dict[str, list[int]] = {t: [] for t in topics}
        self.clock: list[int] = []
        self.order: list[tuple[str, int]] = []
        """('/clock', ns) and (topic, index) as they came."""
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.subscriptions = [self.node.create_subscription(String, t, lambda m, t=t: self._message(t, int(m.data)),
                                                            qos) for t in topics]
        if clock:
            self.node.create_subscription(Clock, '/clock', self._clock,
                                          QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT))
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def _message(self, topic: str, k: int) -> None:
        self.got[topic].append(k)
        self.order.append((topic, k))

    def _clock(self, msg: Any) -> None:
        ns = msg.clock.sec * S + msg.clock.nanosec
        self.clock.append(ns)
        self.order.append(('/clock', ns))

    def run(self, args: list[str], *, until: Any = None, signal_: int | None = None, played: tuple[str, ...] = (),
            player_node: str = 'evsync_player') -> tuple[int, str, str]:
        """Run ``evsync play ARGS`` while listening, started paused and resumed once each subscription
        here to a topic ``played`` (default: all) has matched it (the player sees them first); with
        ``until`` (a test of this), send ``signal_`` once it holds. (exit status, stdout, stderr)"""
        from std_srvs.srv import Trigger
        player = subprocess.Popen([str(BIN / 'evsync'), 'play', '--start-paused', *args], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True)
        resume = self.node.create_client(Trigger, f'/{player_node}/resume')
        waited = [s for s in self.subscriptions if not played or s.topic_name in played]
        resumed = None
        try:
            deadline = time.monotonic() + 60
            while player.poll() is None and time.monotonic() < deadline:
                self.executor.spin_once(timeout_sec=0.02)
                if resumed is None and resume.service_is_ready() and all(
                        s.get_publisher_count() for s in waited):
                    resumed = resume.call_async(Trigger.Request())
                if until is not None and signal_ is not None and until(self):
                    player.send_signal(signal_)
                    signal_ = None
            return self.finish(player)
        finally:
            self.close(player)

    def finish(self, player: subprocess.Popen[str]) -> tuple[int, str, str]:
        """The player's end (exit status, stdout, stderr), what it sent last heard."""
        out, err = player.communicate(timeout=30)
        for _ in range(20):
            self.executor.spin_once(timeout_sec=0.02)
        return player.returncode, out, err

    def close(self, player: subprocess.Popen[str]) -> None:
        player.kill()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def test_clock_publishes_the_bag_s_time_as_it_plays(tmp_path):
    bag = string_bag(tmp_path / 'bag', n=20, step_s=0.1)  # 1.9 s of messages from 10 s
    heard = Heard(('/a',), clock=True)
    code, _, err = heard.run([str(bag), '--clock', '100', '--rate', '2', '--wait-subscribers', '1'])
    assert code == 0, err
    assert heard.got['/a'] == list(range(20))
    clock = heard.clock
    assert len(clock) > 20 and clock == sorted(clock), clock  # 100 Hz for about a second, never back
    # the bag's time: from its first message past its last (the player lingers 0.5 s, 1 s of the bag at --rate 2)
    assert clock[0] == 10 * S and 11_900_000_000 <= clock[-1] <= 11_900_000_000 + 2 * S
    # each message was recorded at k * 0.1 s from 10 s: the clock heard before it is not past that
    last_clock = 0
    for what, value in heard.order:
        if what == '/clock':
            last_clock = value
        else:
            assert last_clock <= 10 * S + value * S // 10 + 50_000_000, (value, last_clock)


def paused_player(heard: Heard, args: list[str]) -> tuple[subprocess.Popen[str], Any]:
    """``evsync play --start-paused ARGS`` started, and a client of its resume service, once the
    service and the player's /a publisher are up (AssertionError after 30 s, or if it exits)."""
    from std_srvs.srv import Trigger
    client = heard.node.create_client(Trigger, '/evsync_player/resume')
    player = subprocess.Popen([str(BIN / 'evsync'), 'play', '--start-paused', *args],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 30
    while not (client.service_is_ready() and heard.node.count_publishers('/a')):
        if time.monotonic() > deadline or player.poll() is not None:
            player.kill()
            raise AssertionError('the paused player is not up')
        heard.executor.spin_once(timeout_sec=0.02)
    return player, client


def spin_while(heard: Heard, going: Any, *, seconds: float = 30.0) -> None:
    """Spin ``heard`` while ``going()`` holds, ``seconds`` at most."""
    deadline = time.monotonic() + seconds
    while going() and time.monotonic() < deadline:
        heard.executor.spin_once(timeout_sec=0.02)


def test_start_paused_sends_nothing_until_its_resume_service_is_called(tmp_path):
    """--start-paused (as ros2 bag play's): the player's publishers are up and /clock runs, held at
    the bag's start, but no message goes until /evsync_player/resume is called; then all of them."""
    from std_srvs.srv import Trigger
    bag = string_bag(tmp_path / 'bag', n=5, step_s=0.05)
    heard = Heard(('/a',), clock=True)
    player, client = paused_player(heard, [str(bag), '--clock', '50'])
    try:
        spin_while(heard, lambda: True, seconds=1.5)
        assert heard.got['/a'] == [] and player.poll() is None, heard.got
        assert heard.clock and set(heard.clock) == {10 * S}, heard.clock
        answer = client.call_async(Trigger.Request())
        spin_while(heard, lambda: player.poll() is None)
        code, out, err = heard.finish(player)
    finally:
        heard.close(player)
    assert code == 0, err
    assert answer.done() and answer.result().success
    assert heard.got['/a'] == list(range(5)) and '/a: 5 messages' in out


def test_the_resume_service_answers_while_the_bag_plays(tmp_path):
    """A caller whose first reply was lost asks again: the player answers it while it plays, as it
    answered the call that resumed it."""
    from std_srvs.srv import Trigger
    bag = string_bag(tmp_path / 'bag', n=60, step_s=0.05)
    heard = Heard(('/a',))
    player, client = paused_player(heard, [str(bag)])
    try:
        answers = [client.call_async(Trigger.Request())]
        spin_while(heard, lambda: not heard.got['/a'])
        answers.append(client.call_async(Trigger.Request()))  # while it plays (3 s of messages)
        spin_while(heard, lambda: not answers[1].done() and player.poll() is None)
        playing_when_answered = player.poll() is None
        spin_while(heard, lambda: player.poll() is None)
        code, _, err = heard.finish(player)
    finally:
        heard.close(player)
    assert code == 0, err
    assert all(a.done() and a.result().success for a in answers), [a.done() for a in answers]
    assert playing_when_answered and len(heard.got['/a']) == 60, heard.got


def test_a_paused_player_whose_context_shuts_down_stops_waiting(tmp_path):
    """The context shut down from outside (rclpy's signal handlers, a program the player runs in) while
    the player waits to be resumed: it raises ExternalShutdownException, as when it spun the service in
    its own thread of control, and does not wait on."""
    import threading

    from rclpy.executors import ExternalShutdownException

    from evsync_ros.ros.play import play
    bag = string_bag(tmp_path / 'bag', n=5, step_s=0.05)
    context = rclpy.context.Context()
    rclpy.init(context=context)
    raised: list[BaseException] = []

    def run() -> None:
        try:
            play(str(bag), start_paused=True, context=context)
        except BaseException as exc:  # noqa: BLE001 (what the test reads)
            raised.append(exc)

    player = threading.Thread(target=run, daemon=True)
    player.start()
    time.sleep(1.0)
    waiting = player.is_alive()
    rclpy.shutdown(context=context)
    player.join(timeout=10.0)
    assert waiting and not player.is_alive(), 'the paused player did not stop'
    assert len(raised) == 1 and isinstance(raised[0], ExternalShutdownException), raised


def test_start_offset_and_playback_duration_play_that_stretch(tmp_path):
    bag = string_bag(tmp_path / 'bag', n=20, step_s=0.1)
    heard = Heard(('/a',))
    code, out, err = heard.run([str(bag), '--start-offset', '0.5', '--playback-duration', '0.8',
                                '--wait-subscribers', '1'])
    assert code == 0, err
    assert heard.got['/a'] == list(range(5, 13)), heard.got  # recorded in [10.5 s, 11.3 s)
    assert '/a: 8 messages' in out


@pytest.mark.parametrize('loop', ['--loop', '-l'])
def test_loop_plays_again_until_interrupted_and_ends_with_130(tmp_path, loop):
    """Ctrl-C ends a --loop (its only end) as it ends every command: 130, what was sent said."""
    bag = string_bag(tmp_path / 'bag', n=5, step_s=0.05)
    heard = Heard(('/a',))
    code, out, err = heard.run([str(bag), loop, '--wait-subscribers', '1'],
                               until=lambda h: len(h.got['/a']) >= 12, signal_=signal.SIGINT)
    assert code == 130, err
    got = heard.got['/a']
    assert got[:12] == [0, 1, 2, 3, 4] * 2 + [0, 1], got
    said = int(out.split('/a: ')[1].split()[0])
    assert said >= len(got) >= 12


@pytest.mark.parametrize('signal_', [signal.SIGINT, signal.SIGTERM])
def test_interrupted_while_playing_ends_with_130(tmp_path, signal_):
    """Issue 52: 130 while playing as while waiting (it was 0 while playing)."""
    bag = string_bag(tmp_path / 'bag', n=40, step_s=0.1)
    heard = Heard(('/a',))
    code, out, err = heard.run([str(bag), '--wait-subscribers', '1'], until=lambda h: len(h.got['/a']) >= 3,
                               signal_=signal_)
    assert code == 130, (out, err)
    assert 3 <= len(heard.got['/a']) < 40 and '/a: ' in out


def test_delay_holds_the_clock_at_the_start_before_each_pass(tmp_path):
    """-d (ros2 bag play --delay): before each pass of a loop, /clock stays at the bag's start for the
    delay, then the messages follow; -r 2 (--rate) plays the pass at twice the pace."""
    bag = string_bag(tmp_path / 'bag', n=5, step_s=0.05)
    heard = Heard(('/a',), clock=True)
    code, _, err = heard.run([str(bag), '-l', '-d', '0.6', '-r', '2', '--clock', '100', '--wait-subscribers', '1'],
                             until=lambda h: len(h.got['/a']) >= 7, signal_=signal.SIGINT)
    assert code == 130, err
    # between the first pass's last message and the second's first: /clock back at the start, held there
    order = heard.order
    last = order.index(('/a', 4))
    again = order.index(('/a', 0), last)
    held = [v for what, v in order[last:again] if what == '/clock' and v == 10 * S]
    assert len(held) >= 20, order[last:again]  # 100 Hz for 0.6 s
    ticks = [v for what, v in order[:last] if what == '/clock' and v > 10 * S]
    assert ticks and max(ticks) <= 10 * S + 4 * S // 20 + 100_000_000


def test_short_flags_are_ros2_bag_play_s(tmp_path):
    """-r rate, -l loop, -p start paused, -d delay, -s storage, -m remap, as ros2 bag play names them."""
    from evsync_ros.cli.main import parse

    bag = string_bag(tmp_path / 'bag', n=1)
    _, args = parse(['play', '-r', '2', '-l', '-p', '-d', '1.5', '-s', 'sqlite3', '-m', '/a:=/b', str(bag)])
    assert (args.rate, args.loop, args.start_paused, args.delay, args.storage, args.remap, args.bag) == (
        2.0, True, True, 1.5, 'sqlite3', ['/a:=/b'], str(bag))


def test_storage_not_the_bag_s_is_refused_naming_both(tmp_path):
    bag = string_bag(tmp_path / 'bag', n=3)  # sqlite3
    done = subprocess.run([str(BIN / 'evsync'), 'play', str(bag), '-s', 'mcap'], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 1, done.stderr
    assert f'{bag}: its storage is sqlite3, not mcap' in done.stderr


def test_qos_profile_overrides_win_over_the_recorded_qos(tmp_path):
    """--qos-profile-overrides-path, in ros2 bag play's YAML: the topics it names get its profile."""
    overrides = tmp_path / 'qos.yaml'
    overrides.write_text('/events:\n  reliability: reliable\n  history: keep_last\n  depth: 10\n'
                         '/plain:\n  reliability: best_effort\n  durability: transient_local\n  depth: 5\n')
    seen = seen_qos(['--qos-profile-overrides-path', str(overrides)], bag_with_qos(tmp_path / 'bag'))
    assert seen == {'/events': (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE),
                    '/info': (ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL),
                    '/plain': (ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.TRANSIENT_LOCAL)}


@pytest.mark.parametrize(('text', 'said'), [('/a:\n  reliabilty: reliable\n', "unknown QoS policy 'reliabilty'"),
                                            ('/a:\n  reliability: sometimes\n', 'reliability'),
                                            ('/a:\n  reliability: reliable\n', 'History and/or depth'),
                                            ('- /a\n', 'a mapping of topic to profile')])
def test_a_bad_qos_override_file_is_named_with_what_is_wrong(tmp_path, text, said):
    from evsync_ros.errors import ParameterError
    from evsync_ros.ros.play import load_qos_overrides

    path = tmp_path / 'qos.yaml'
    path.write_text(text)
    with pytest.raises(ParameterError, match=str(path)) as caught:
        load_qos_overrides(path)
    assert said in str(caught.value)


def test_a_split_compressed_bag_plays_whole(tmp_path):
    """Issue 52: a bag in several storage files (restamp --max-bag-size, as ros2 bag record splits),
    each compressed whole, plays as one."""
    bag = string_bag(tmp_path / 'bag', n=12, step_s=0.02,
                     layout=Layout(max_bytes=30, compression=Compression.FILE, compression_format='zstd'))
    assert len(list(bag.glob('bag_*.db3.zstd'))) >= 3
    heard = Heard(('/a',))
    code, out, err = heard.run([str(bag), '--wait-subscribers', '1', '-s', 'sqlite3'])
    assert code == 0, err
    assert heard.got['/a'] == list(range(12)) and '/a: 12 messages' in out


def test_wait_subscribers_waits_only_on_the_topics_someone_subscribes_to(tmp_path):
    """A bag with a topic nobody subscribes to (/b): the player starts once /a has its subscriber,
    rather than failing after its timeout."""
    bag = string_bag(tmp_path / 'bag', ('/a', '/b'), n=5)
    heard = Heard(('/a',))
    code, out, err = heard.run([str(bag), '--wait-subscribers', '1'])
    assert code == 0, err
    assert heard.got['/a'] == list(range(5))
    assert '/a: 5 messages' in out and '/b: 5 messages' in out


@pytest.mark.parametrize('loop', [[], ['--loop']])
def test_messages_its_index_lists_that_cannot_be_read_are_said_after_playing(tmp_path, loop):
    """A message that no reader reads (its mcap channel id names none), which the file's statistics
    list: the player plays the rest and then exits 1 (its status of a clear error about the bag), naming
    the bag and the topic, rather than 0; with --loop, at the end of the first pass rather than play
    on."""
    bag = tmp_path / 'bag'
    with BagWriter(bag, storage='mcap') as w:
        conn = w.add_topic('/a', 'std_msgs/msg/String')
        for k in range(5):
            w.write(conn, 10 * S + round(k * 0.05 * S), serialize_message(String(data=str(k))))
    (mcap,) = bag.glob('*.mcap')
    edit_mcap_channel(mcap, mcap, channel=99, which=3)
    heard = Heard(('/a',))
    code, out, err = heard.run([str(bag), '--wait-subscribers', '1', *loop])
    assert heard.got['/a'] == [0, 1, 3, 4]
    assert code == 1 and f'{bag}: messages its index lists could not be read: 1 of the 5 of /a' in err, (out, err)


def test_options_before_the_bag_and_ros_arguments_after_ros_args(tmp_path):
    bag = string_bag(tmp_path / 'bag', ('/a', '/b'), n=5)
    heard = Heard(('/a', '/b'))
    code, _, err = heard.run(['--topics', '/a', str(bag), '--wait-subscribers', '1', '--ros-args',
                                '-r', '__node:=renamed_player'], played=('/a',), player_node='renamed_player')
    assert code == 0, err
    assert heard.got == {'/a': list(range(5)), '/b': []}


@pytest.mark.parametrize('typo', [['--clok'], ['--loop', '--ros-arg'], ['-x', '1']])
def test_an_unknown_option_is_refused_not_passed_on(tmp_path, typo):
    """Only what follows --ros-args goes to ROS: a typo stops it with the option named."""
    bag = string_bag(tmp_path / 'bag', n=3)
    done = subprocess.run([str(BIN / 'evsync'), 'play', str(bag), *typo], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert 'unrecognized arguments' in done.stderr and typo[-2 if typo[0] == '-x' else -1] in done.stderr


def test_a_ros_remap_before_ros_args_is_taken_for_the_rate_and_refused(tmp_path):
    """-r is ros2 bag play's rate: a ROS remap typed before --ros-args is named as a rate that is none."""
    bag = string_bag(tmp_path / 'bag', n=3)
    done = subprocess.run([str(BIN / 'evsync'), 'play', str(bag), '-r', '/a:=/b'], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2 and 'argument -r/--rate: invalid float value' in done.stderr, done.stderr
