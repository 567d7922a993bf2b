"""One message of each event type through real rclpy and Fast DDS on loopback."""

import time

import pytest

rclpy = pytest.importorskip('rclpy', reason='rclpy is installed by ./dev setup')
from builtin_interfaces.msg import Time  # noqa: E402
from dvs_msgs.msg import Event as DvsEvent  # noqa: E402
from dvs_msgs.msg import EventArray as DvsEventArray  # noqa: E402
from event_camera_msgs.msg import EventPacket  # noqa: E402
from prophesee_event_msgs.msg import Event as PropheseeEvent  # noqa: E402
from prophesee_event_msgs.msg import EventArray as PropheseeEventArray  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402


def _packet():
    msg = EventPacket(height=480, width=640, seq=7, time_base=123_456_789, encoding='evt3',
                      is_bigendian=False, events=bytes(range(256)) * 4)
    msg.header.stamp = Time(sec=1_763_700_000, nanosec=42)
    msg.header.frame_id = 'prophesee'
    return msg


def _array(array_type, event_type):
    msg = array_type(height=260, width=346)
    msg.header.stamp = Time(sec=12, nanosec=999_999_999)
    msg.events = [event_type(x=i, y=2 * i, ts=Time(sec=12, nanosec=1000 * i), polarity=bool(i % 2))
                  for i in range(100)]
    return msg


@pytest.mark.parametrize(
    ('msg_type', 'make'),
    [
        (EventPacket, _packet),
        (DvsEventArray, lambda: _array(DvsEventArray, DvsEvent)),
        (PropheseeEventArray, lambda: _array(PropheseeEventArray, PropheseeEvent)),
    ],
    ids=['event_camera_msgs/EventPacket', 'dvs_msgs/EventArray', 'prophesee_event_msgs/EventArray'],
)
def test_publish_and_receive_over_loopback(msg_type, make):
    context = rclpy.context.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('evsync_loopback_test', context=context)
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        received: list[object] = []
        node.create_subscription(msg_type, 'loopback', received.append, qos)
        pub = node.create_publisher(msg_type, 'loopback', qos)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        sent = make()
        deadline = time.monotonic() + 20.0
        while not received and time.monotonic() < deadline:
            if pub.get_subscription_count():
                pub.publish(sent)
            executor.spin_once(timeout_sec=0.1)
        assert received, 'nothing arrived over loopback within 20 s'
        assert received[0] == sent
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
