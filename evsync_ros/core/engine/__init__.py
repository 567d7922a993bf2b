"""The one estimation engine behind the node, the bag tools and the array API (docs/method.md,
"One engine"): ``Engine`` fed per camera with event and arrival times, ``plan`` where windows go,
``windows`` one window's fit and what a camera's windows say, ``lock`` the lock state machine,
``arrival`` the arrival-lag lines. numpy only."""

from evsync_ros.core.engine.engine import Engine, Status
from evsync_ros.core.engine.lock import State
from evsync_ros.core.engine.params import LIVE_SEARCH_NS, OnlineParams
from evsync_ros.core.results import Method

__all__ = ['LIVE_SEARCH_NS', 'Engine', 'Method', 'OnlineParams', 'State', 'Status']
