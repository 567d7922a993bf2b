"""Event message definitions, field for field as upstream, for rosbags' type system.

The interface packages built for rclpy come from ``interfaces/*/msg/*.msg`` in this repository;
a test checks that these texts declare the same fields. Upstream sources:
ros-event-camera/event_camera_msgs (msg_ros2/EventPacket.msg), ros-event-camera/dvs_msgs and
ros-event-camera/prophesee_event_msgs (Event.msg, EventArray.msg).
"""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

EVENT_PACKET = 'event_camera_msgs/msg/EventPacket'
DVS_EVENT = 'dvs_msgs/msg/Event'
DVS_EVENT_ARRAY = 'dvs_msgs/msg/EventArray'
PROPHESEE_EVENT = 'prophesee_event_msgs/msg/Event'
PROPHESEE_EVENT_ARRAY = 'prophesee_event_msgs/msg/EventArray'

_EVENT = """\
uint16 x
uint16 y
builtin_interfaces/Time ts
bool polarity
"""

_EVENT_ARRAY = """\
std_msgs/Header header
uint32 height
uint32 width
Event[] events
"""

#: Definitions in dependency order (an Event before the EventArray that holds it).
MSG_DEFINITIONS: dict[str, str] = {
    EVENT_PACKET: """\
std_msgs/Header header
uint32 height
uint32 width
uint64 seq
uint64 time_base
string encoding
bool is_bigendian
uint8[] events
""",
    DVS_EVENT: _EVENT,
    DVS_EVENT_ARRAY: _EVENT_ARRAY,
    PROPHESEE_EVENT: _EVENT,
    PROPHESEE_EVENT_ARRAY: _EVENT_ARRAY,
}

#: The event array types (one event per struct element, absolute ROS time per event).
EVENT_ARRAY_TYPES = (DVS_EVENT_ARRAY, PROPHESEE_EVENT_ARRAY)
#: Every event message type evsync_ros understands.
EVENT_TYPES = (EVENT_PACKET, *EVENT_ARRAY_TYPES)


@lru_cache(maxsize=1)
def event_typestore() -> Typestore:
    """A ROS 2 Jazzy typestore with the event message types registered."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(dict(event_fielddefs()))
    return store


@lru_cache(maxsize=1)
def event_fielddefs() -> dict[str, Any]:
    """The event message types as ``event_typestore`` registers them (rosbags' field definitions), for
    a caller that compares definitions: parsing them costs a tenth of making ROS 2 Jazzy's store."""
    from rosbags.typesys import get_types_from_msg

    types: dict[str, Any] = {}
    for name, text in MSG_DEFINITIONS.items():
        types.update(get_types_from_msg(text, name))
    return types
