"""``evsync_node --help``: how to start the node, and every parameter with its default and meaning."""

from __future__ import annotations

import textwrap

from evsync_ros.errors import ParameterError
from evsync_ros.ros.parameters import NODE_PARAMETERS, RUNTIME, expected, node_defaults, shipped_parameters

__all__ = ['usage', 'wants_help']

HEAD = """\
usage: evsync_node [-h] [--ros-args [-p NAME:=VALUE ...] [--params-file FILE] ...]

Synchronises event cameras live: estimates each camera's clock offset (and drift) against the
reference from the event densities, and republishes every stream restamped onto the reference's
timeline on <topic>/synced, with /evsync/offsets, /diagnostics and /evsync/status.

  ./dev run evsync_node --ros-args --params-file rig.yaml
  ros2 run evsync_ros evsync_node --ros-args --params-file rig.yaml -p reference:=host

The node in full: docs/node.md. Parameters, with their defaults as installed in
{path} (* may be set while it runs: ros2 param set); rclpy's
qos_overrides.<topic>.<publisher|subscription>.<history|depth|reliability|durability> win over
qos, qos_depth and output_reliability for the topics they name:
"""


def wants_help(argv: list[str]) -> bool:
    """Whether a command line asks for this help (before any ``--ros-args``)."""
    plain = argv[1:argv.index('--ros-args')] if '--ros-args' in argv else argv[1:]
    return '-h' in plain or '--help' in plain


def usage() -> str:
    """The help text."""
    try:
        path, defaults = str(shipped_parameters()), node_defaults()
    except ParameterError as exc:  # a broken install: say so, and the parameters still
        path, defaults = f'config/evsync.yaml ({exc})', {}
    lines = [HEAD.format(path=path)]
    for name, spec in NODE_PARAMETERS.items():
        default = defaults.get(name)
        shown = 'left out' if default is None else repr(default)
        lines.append(f'  {name}{" *" if name in RUNTIME else ""}  ({expected(spec)}; default {shown})')
        lines += textwrap.wrap(spec.description, width=96, initial_indent=' ' * 6, subsequent_indent=' ' * 6)
    return '\n'.join(lines) + '\n'
