"""The adapters' errors. The adapters import nothing from evsync_ros, so these stand alone; the
front ends report them beside evsync_ros's own (``evsync_ros.errors.EXPECTED_ERRORS``)."""

from __future__ import annotations


class AdapterError(Exception):
    """Base class of every error the adapters raise on purpose."""


class MessageError(AdapterError, ValueError):
    """A serialized message cannot be decoded or restamped (truncated, wrong encoding, big-endian,
    a corrected time its field cannot hold, ...). The text names the message type and the field."""
