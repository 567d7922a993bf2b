"""evsync play (issue 24): each topic goes out with the QoS it was recorded with, as ros2 bag play
does, reliable where the bag recorded none; --reliable and --best-effort force one for all. Real
DDS on loopback: the player's publishers are seen as a subscriber sees them."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

rclpy = pytest.importorskip('rclpy', reason='rclpy is installed by ./dev setup')

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from evsync_ros.bag.writer import BagWriter  # noqa: E402

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
