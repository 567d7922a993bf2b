"""Typed errors of evsync_ros, every layer's in one place. Every error names the input it is about.

The core's (``EvsyncError``, ``ParameterError``, ``StreamError``) live in ``evsync_ros.core.errors``
and the adapters' (``MessageError``) in ``msg_adapters.errors``, so that neither layer imports a
front end; the front ends import them from here.
"""

from __future__ import annotations

from evsync_ros.core.errors import EvsyncError, ParameterError, StreamError
from msg_adapters.errors import AdapterError, MessageError

__all__ = ['EXPECTED_ERRORS', 'AdapterError', 'BagError', 'EvsyncError', 'MessageError', 'ParameterError',
           'StreamError', 'unreadable']


class BagError(EvsyncError):
    """A rosbag2 input or output cannot be used."""


def unreadable(name: object, exc: BaseException) -> BagError:
    """The error of a storage file that a reader failed on (``exc``, whatever its class), naming the bag."""
    return BagError(f'{name}: cannot be read ({type(exc).__name__}: {exc}); the storage file is corrupt or '
                    'truncated')


EXPECTED_ERRORS: tuple[type[Exception], ...] = (EvsyncError, AdapterError)
"""What the front ends report as a clear error (exit status 2) rather than a traceback: evsync_ros's
own errors and the adapters' (``MessageError``), which stand apart so that ``msg_adapters`` imports
nothing from evsync_ros."""
