"""The core's typed errors. Every error names the input it is about."""

from __future__ import annotations


class EvsyncError(Exception):
    """Base class of every error raised on purpose by evsync_ros."""


class ParameterError(EvsyncError, ValueError):
    """A parameter is out of range (negative bin width, NaN threshold, ...)."""


class StreamError(EvsyncError, ValueError):
    """An event-time stream cannot be used (empty, wrong dtype or shape)."""
