"""Numeric per-camera status for plotting tools: one ``std_msgs/Float64`` topic per quantity.

PlotJuggler and Foxglove plot a message's numeric fields as they are; /diagnostics carries its values
as strings and /evsync/offsets as two times, so neither plots the offset without arithmetic. Under
``status_topic`` (default ``/evsync/status``) the node publishes, per camera and per diagnostics
period, ``<status_topic><camera topic>/<field>`` for the fields of ``FIELDS``, e.g.
``/evsync/status/cam_left/events/offset_ms`` (PlotJuggler's curve ``.../offset_ms/data``, Foxglove's
message path ``.../offset_ms.data``). A quantity not known yet (no correction, no uncertainty) is NaN,
which both tools draw as a gap. Standard messages only: an interface package of our own could not be
built by colcon inside this ament_python package. ``layout`` writes a PlotJuggler layout of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine import State, Status

STATE_CODES: dict[State, int] = {State.WAITING: 0, State.SEEDED: 1, State.ESTIMATING: 2, State.LOCKED: 3,
                                 State.LOST: 4}
"""``state`` as a number: 0 waiting, 1 seeded, 2 estimating, 3 locked, 4 lost."""


@dataclass(frozen=True)
class Field:
    name: str
    description: str


FIELDS: tuple[Field, ...] = (
    Field('offset_ms', "the estimated offset at the camera's newest event (ms, added to its times; NaN before "
                       'its first lock, as /diagnostics leaves offset_ns empty)'),
    Field('skew_ppm', 'the rate difference in force (ppm)'),
    Field('offset_std_ms', 'standard error of the offset (ms; refined method)'),
    Field('skew_std_ppm', 'standard error of the skew (ppm; refined method)'),
    Field('state', 'state code: 0 waiting, 1 seeded, 2 estimating, 3 locked, 4 lost'),
    Field('confidence', 'share of the windows with a clear peak that agree with the line'),
    Field('messages_lost', 'messages lost before the node, counted from EventPacket seq gaps'),
)
NAMES = tuple(f.name for f in FIELDS)


def field_topic(status_topic: str, camera: str, name: str) -> str:
    """The topic of one camera's quantity: ``<status_topic><camera>/<name>``."""
    return f'{status_topic.rstrip("/")}{camera}/{name}'


def camera_values(s: Status, *, correction: ClockCorrection | None, last_time_ns: int | None, lost: int
           ) -> dict[str, float]:
    """One camera's numbers (``FIELDS``) from its online status and the correction in force
    (``correction``: what its messages get, None before it has one)."""
    nan = math.nan
    if correction is None:
        offset, skew = nan, nan
    else:
        at = correction.anchor_ns if last_time_ns is None else last_time_ns
        offset, skew = (correction.apply_one(at) - at) / 1e6, correction.skew_ppm
    return {
        'offset_ms': offset, 'skew_ppm': skew,
        'offset_std_ms': nan if s.uncertainty_ns is None else s.uncertainty_ns / 1e6,
        'skew_std_ppm': nan if s.skew_uncertainty_ppm is None else float(s.skew_uncertainty_ppm),
        'state': float(STATE_CODES[s.state]), 'confidence': float(s.confidence), 'messages_lost': float(lost),
    }


PLOTS: tuple[tuple[str, str], ...] = (('offset_ms', 'offset (ms)'), ('offset_std_ms', 'offset standard error (ms)'),
                                      ('skew_ppm', 'skew (ppm)'), ('state', 'state (3 locked)'))
"""The layout's plots, one above the other: the quantity and its title."""
COLORS = ('#1f77b4', '#d62728', '#1ac938', '#ff7f0e', '#f14cc1', '#9467bd', '#17becf', '#bcbd22')


def layout(cameras: list[str], *, status_topic: str = '/evsync/status') -> str:
    """A PlotJuggler layout (XML) plotting every camera's offset, its standard error, skew and state,
    streaming from the ROS2 Topic Subscriber. ``cameras``: the event topics, the node's ``topics``."""
    n = len(PLOTS)
    sizes = ';'.join(f'{1 / n:.6f}' for _ in PLOTS)
    lines = ["<?xml version='1.0' encoding='UTF-8'?>", '<root>',
             ' <tabbed_widget name="Main Window" parent="main_window">',
             '  <Tab containers="1" tab_name="evsync">', '   <Container>',
             f'    <DockSplitter count="{n}" orientation="-" sizes="{sizes}">']
    for name, title in PLOTS:
        lines += [f'     <DockArea name={quoteattr(title)}>',
                  '      <plot flip_x="false" flip_y="false" mode="TimeSeries" style="Lines">',
                  '       <range bottom="0" left="0" right="1" top="1"/>', '       <limitY/>']
        for i, cam in enumerate(cameras):
            curve = field_topic(status_topic, cam, name) + '/data'
            lines.append(f'       <curve color="{COLORS[i % len(COLORS)]}" name={quoteattr(curve)}/>')
        lines += ['      </plot>', '     </DockArea>']
    topics = ';'.join(field_topic(status_topic, cam, name) for cam in cameras for name, _ in PLOTS)
    lines += ['    </DockSplitter>', '   </Container>', '  </Tab>', '  <currentTabIndex index="0"/>',
              ' </tabbed_widget>', ' <use_relative_time_offset enabled="1"/>', ' <Plugins>',
              '  <plugin ID="ROS2 Topic Subscriber">', '   <use_header_stamp value="false"/>',
              '   <discard_large_arrays value="true"/>', '   <max_array_size value="100"/>',
              '   <boolean_strings_to_number value="true"/>', '   <remove_suffix_from_strings value="true"/>',
              f'   <selected_topics value={quoteattr(topics)}/>', '  </plugin>', ' </Plugins>',
              ' <previouslyLoaded_Streamer value="ROS2 Topic Subscriber"/>', ' <customMathEquations/>',
              ' <snippets/>', '</root>', '']
    return '\n'.join(lines)
