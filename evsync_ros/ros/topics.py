"""A message path's topics on a node: each stream's subscription and output, each companion's,
with the QoS its parameters and ``qos_overrides`` give them (``ros.qos``)."""

from __future__ import annotations

import functools
from collections.abc import Collection

from rclpy.node import Node

from evsync_ros.ros.messages import companion_class, message_class
from evsync_ros.ros.modes import Republish
from evsync_ros.ros.parameters import NodeConfig
from evsync_ros.ros.path import MessagePath
from evsync_ros.ros.qos import companion_qos, events_qos, output_qos, publisher, subscription
from evsync_ros.ros.streams import CompanionState, StreamState
from msg_adapters.registry import Restamper, decoder_for

__all__ = ['open_companions', 'open_stream']


def open_stream(node: Node, path: MessagePath, config: NodeConfig, index: int) -> StreamState:
    """Camera ``index`` of ``topics`` into ``path``: its output (``republish: all``), then its input."""
    topic, msgtype, output = config.topics[index], config.types[index], config.outputs[index]
    st = StreamState(topic, output, decoder_for(msgtype), Restamper(msgtype, live=True), msgtype=msgtype,
                     trigger_channel=config.trigger_channels.get(topic))
    cls = message_class(msgtype)
    if config.republish is Republish.ALL:
        st.publisher = publisher(node, cls, output, output_qos(config))
    path.streams[topic] = st
    st.subscription = subscription(node, cls, topic, functools.partial(path.on_message, st), events_qos(config))
    return st


def open_companions(node: Node, path: MessagePath, config: NodeConfig, cameras: Collection[str]) -> None:
    """The companions of ``cameras`` into ``path`` (none with ``republish: none``: nothing of theirs
    to do). A type without a leading Header: ParameterError naming it."""
    if config.republish is Republish.NONE:
        return
    for comp in config.companions:
        if comp.camera not in cameras:
            continue
        cls = companion_class(comp.topic, comp.msgtype)
        take, offer = companion_qos(node, comp.topic, events_qos(config), config.qos_depth)
        cs = CompanionState(comp.topic, comp.camera, comp.output)
        path.streams[comp.camera].timed = True
        cs.publisher = publisher(node, cls, comp.output, offer)
        path.companions[comp.topic] = cs
        cs.subscription = subscription(node, cls, comp.topic, functools.partial(path.on_companion, cs), take)
