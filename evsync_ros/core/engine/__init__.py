"""The one estimation engine behind the node, the bag tools and the array API (docs/method.md, "One
engine"). numpy only."""

from evsync_ros.core.engine.engine import Engine, Status
from evsync_ros.core.engine.lock import State
from evsync_ros.core.engine.params import LIVE_SEARCH_NS, EngineParams
from evsync_ros.core.results import Method

__all__ = ['LIVE_SEARCH_NS', 'Engine', 'EngineParams', 'Method', 'State', 'Status']
