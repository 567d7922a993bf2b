"""What the adapters expect of a clock correction, and what their decoders and restampers offer.

Structural types (``typing.Protocol``): the adapters take any object with these members, so they
need nothing from the estimation core, whose ``ClockCorrection`` is one such correction. A decoder
here plays the part of event_camera_codecs' decoder base class: one per stream, stateful, fed the
stream's messages in order.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from msg_adapters.edges import TriggerEdges
from msg_adapters.events import Events, Stepped

Bytes = bytes | bytearray | memoryview
"""A serialized (CDR) message as rclpy raw subscriptions and rosbags hand it over."""


class Correction(Protocol):
    """How a camera's times map onto the reference timeline: ``t + offset_ns + skew_ppm * 1e-6 *
    (t - anchor_ns)`` (int64 ns)."""

    @property
    def offset_ns(self) -> int: ...

    @property
    def skew_ppm(self) -> float: ...

    @property
    def anchor_ns(self) -> int: ...

    @property
    def is_identity(self) -> bool: ...

    def apply(self, t: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        """The corrected times of an int64 ns array (a new array)."""

    def apply_one(self, t: int) -> int:
        """The corrected time of one int ns."""


class Decoder(Protocol):
    """One stream's messages to event times (int64 ns on the camera's timeline), in stream order."""

    @property
    def anomalies(self) -> Mapping[str, int]:
        """Odd input met so far and counted by kind (nothing is dropped unseen)."""

    def decode(self, raw: Bytes, *, xyp: bool = False) -> tuple[Any, Events]:
        """(the message's parsed fields, its events); ``xyp`` also decodes x, y and polarity.
        Raises ``MessageError`` when the bytes do not hold a message of the stream's type, leaving
        the stream's state as it was."""

    def decode_times(self, raw: Bytes) -> Any:
        """``decode(raw)[1].t`` (the same state and anomalies after it), by the quickest way there is."""

    def decode_ros1_times(self, raw: Bytes) -> Any:
        """``decode_times`` of a ROS 1 message's CDR where the decoder reads the ROS 1 bytes as they
        are; None, nothing moved, where they must be converted first."""


class EdgeDecoder(Decoder, Protocol):
    """A decoder that also gives each message's trigger edges, on its events' timeline, from the same
    walk (every decoder ``registry.decoder_for`` makes is one)."""

    def decode_edges(self, raw: Bytes, *, xyp: bool = False) -> tuple[Any, Events, TriggerEdges]:
        """``decode(raw, xyp=xyp)``, and the message's trigger edges (none where its type or encoding
        carries none); the same state and anomalies after it."""

    def decode_times_edges(self, raw: Bytes) -> tuple[Any, TriggerEdges]:
        """``decode_edges(raw)``'s event times and edges, by the quickest way there is."""

    def step(self, raw: Bytes, *, grid_ns: int, counts: npt.NDArray[np.int32], restamper: Any,
             correction: Correction | None, edges: bool = False) -> Stepped | None:
        """A live stream's next message decoded as ``decode_times`` decodes it (with ``edges``, as
        ``decode_times_edges``: ``Stepped.edges``), counted on the grid of ``grid_ns`` into ``counts``
        and, given a ``correction``, restamped as the stream's ``restamper`` would, in one C call; None,
        nothing moved, for a message that call does not take."""


class Restamper(Protocol):
    """One stream's messages restamped by a correction, in stream order."""

    def restamp(self, raw: Bytes, correction: Correction) -> bytearray:
        """A corrected copy of one serialized message (what moves depends on the type and encoding).
        Raises ``MessageError`` when the message cannot be read or a corrected time leaves its field."""
