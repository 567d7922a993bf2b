"""The live names of the engine (``core.engine``), kept for the node and for code written against them:
``OnlineSync`` is the ``Engine`` fed live."""

from evsync_ros.core.engine import LIVE_SEARCH_NS, Engine, Method, OnlineParams, State, Status
from evsync_ros.core.engine.arrival import LATE_NS
from evsync_ros.core.engine.params import LATENCY_LIMIT_NS

OnlineSync = Engine

__all__ = ['LATENCY_LIMIT_NS', 'LATE_NS', 'LIVE_SEARCH_NS', 'Method', 'OnlineParams', 'OnlineSync', 'State', 'Status']
