"""The QoS of the node's event and companion topics, and rclpy's QoS overrides on them.

Every publisher and subscription of the message path is made with rclpy's ``QoSOverridingOptions``
(history, depth, reliability, durability), so ``qos_overrides.<topic>.<publisher|subscription>.<policy>``
parameters win over what ``qos``, ``qos_depth`` and ``output_reliability`` make for the topics
they name, as in any rclpy or rclcpp node."""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSPolicyKind,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.qos_overriding_options import QoSOverridingOptions

from evsync_ros.ros.modes import Qos, Reliability
from evsync_ros.ros.parameters import NodeConfig

__all__ = ['OVERRIDABLE', 'companion_qos', 'events_qos', 'output_qos', 'publisher', 'subscription']

OVERRIDABLE = QoSOverridingOptions([QoSPolicyKind.HISTORY, QoSPolicyKind.DEPTH, QoSPolicyKind.RELIABILITY,
                                    QoSPolicyKind.DURABILITY])
"""The policies a ``qos_overrides`` parameter may set on the message path's topics."""
INPUT_RELIABILITY = {Qos.SENSOR_DATA: qos_profile_sensor_data.reliability, Qos.RELIABLE: ReliabilityPolicy.RELIABLE}


def events_qos(config: NodeConfig) -> QoSProfile:
    """The QoS of event inputs (``qos``, ``qos_depth``)."""
    return QoSProfile(depth=config.qos_depth, history=HistoryPolicy.KEEP_LAST,
                      reliability=INPUT_RELIABILITY[config.qos], durability=DurabilityPolicy.VOLATILE)


def output_qos(config: NodeConfig) -> QoSProfile:
    """The QoS of the restamped event outputs: depth ``qos_depth``, reliable unless both
    ``output_reliability`` and ``qos`` say best effort (a reliable writer serves best-effort
    readers too)."""
    reliable = config.output_reliability is Reliability.RELIABLE or config.qos is Qos.RELIABLE
    return QoSProfile(depth=config.qos_depth, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=qos_profile_sensor_data.durability)


def companion_qos(node: Node, topic: str, events: QoSProfile, depth: int) -> tuple[QoSProfile, QoSProfile]:
    """(subscription, republisher) QoS of a companion: as its publisher offers it (reliability and
    durability: a transient-local camera_info stays so for late subscribers) when one is up as
    the node starts; else taken as the events are, offered reliable (which serves best-effort
    subscribers too)."""
    infos = node.get_publishers_info_by_topic(topic)
    if infos:
        offered = infos[0].qos_profile
        same = QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST,
                          reliability=offered.reliability, durability=offered.durability)
        return same, copy.copy(same)
    return events, QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)


def publisher(node: Node, cls: Any, topic: str, qos: QoSProfile) -> Any:
    """A publisher of ``cls`` on ``topic`` with ``qos``, unless ``qos_overrides`` say otherwise."""
    return node.create_publisher(cls, topic, copy.copy(qos), qos_overriding_options=OVERRIDABLE)


def subscription(node: Node, cls: Any, topic: str, callback: Callable[[bytes], None], qos: QoSProfile) -> Any:
    """A raw subscription to ``topic`` with ``qos``, unless ``qos_overrides`` say otherwise."""
    return node.create_subscription(cls, topic, callback, copy.copy(qos), qos_overriding_options=OVERRIDABLE,
                                    raw=True)
