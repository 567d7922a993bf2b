"""The node's parameters as rclpy sees them: each declared (typed, ranged, read only unless it may
change while the node runs), checked (``ros.parameters``), and what the node was given beyond them
warned about by name."""

from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterUninitializedException,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

from evsync_ros.errors import ParameterError
from evsync_ros.ros.modes import Kind
from evsync_ros.ros.parameters import (
    NODE_PARAMETERS,
    QOS_OVERRIDES,
    RUNTIME,
    NodeConfig,
    expected,
    node_config,
    node_defaults,
    unknown_parameters,
)

__all__ = ['declare_parameters', 'given', 'parameter_value', 'qos_overrides', 'warn_unknown']

_KINDS = {Kind.STRING: ParameterType.PARAMETER_STRING, Kind.STRING_ARRAY: ParameterType.PARAMETER_STRING_ARRAY,
          Kind.DOUBLE: ParameterType.PARAMETER_DOUBLE, Kind.DOUBLE_ARRAY: ParameterType.PARAMETER_DOUBLE_ARRAY,
          Kind.INTEGER: ParameterType.PARAMETER_INTEGER}
DOUBLES = (Kind.DOUBLE, Kind.DOUBLE_ARRAY)


def declare_parameters(node: Node) -> NodeConfig:
    """Declare every node parameter on ``node`` (read only, typed, ranged) and return the checked
    configuration; ParameterError names the parameter that does not check out."""
    defaults = node_defaults()
    for name, spec in NODE_PARAMETERS.items():
        descriptor = ParameterDescriptor(description=spec.description, type=_KINDS[spec.kind],
                                         read_only=name not in RUNTIME)
        if spec.kind in DOUBLES:
            descriptor.floating_point_range = [FloatingPointRange(from_value=spec.low, to_value=spec.high)]
        elif spec.kind is Kind.INTEGER and spec.low is not None and spec.high is not None:
            descriptor.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high))]
        if spec.choices:
            descriptor.additional_constraints = f'one of: {", ".join(spec.choices)}'
        try:  # an optional parameter left out (an empty array): declared by its type alone
            default = defaults[name] if defaults[name] is not None else Parameter.Type.STRING_ARRAY
            node.declare_parameter(name, default, descriptor)
        except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
            # rclpy's own check of a --ros-args or params-file value: say it as the others are said
            whole = (' (write whole numbers as decimals: 1.0, not 1)'
                     if spec.kind in DOUBLES and isinstance(exc, InvalidParameterTypeException) else '')
            raise ParameterError(f'node {node.get_fully_qualified_name()}: {name} must be '
                                 f'{expected(spec)}{whole}: {exc}') from exc
    values = {name: parameter_value(node, name) for name in NODE_PARAMETERS}
    return node_config(values, source=f'node {node.get_fully_qualified_name()}')


def parameter_value(node: Node, name: str) -> Any:
    """A parameter's value (None: an optional one left out)."""
    try:
        return node.get_parameter(name).value
    except ParameterUninitializedException:
        return None


def given(node: Node) -> dict[str, Any]:
    """Every parameter value ``node`` was given (``-p``, ``--params-file`` entries that rcl matched
    to it, overrides in code), declared or not: rclpy keeps them in the node's overrides, which it
    has no public reader of."""
    return {name: p.value for name, p in node._parameter_overrides.items()}


def qos_overrides(node: Node) -> dict[str, Any]:
    """The ``qos_overrides.*`` parameters ``node`` was given (``ros.qos``)."""
    return {name: value for name, value in given(node).items() if name.startswith(QOS_OVERRIDES)}


def warn_unknown(node: Node, config: NodeConfig) -> None:
    """Warn, once, of each parameter ``node`` was given that it has not (a misspelt name with the
    nearest it has), of each deprecated one, and of each QoS override of a topic the node neither
    subscribes to nor publishes."""
    unknown, deprecated = unknown_parameters(given(node), entities=entities(config))
    log = node.get_logger()
    for name in unknown:
        log.warning(f'parameter {name} is not a parameter of evsync_node: left unused (evsync_node --help lists '
                    'them)')
    for name in deprecated:
        log.warning(f'parameter {name} is deprecated: left unused')


def entities(config: NodeConfig) -> set[str]:
    """``<topic>.<publisher|subscription>`` of every topic the message path takes or offers, as
    ``qos_overrides`` name them."""
    taken = [*config.topics, *(c.topic for c in config.companions)]
    offered = [*config.outputs, *(c.output for c in config.companions)]
    return {f'{t}.subscription' for t in taken} | {f'{t}.publisher' for t in offered}
