"""Recorded bags (rosbags): reading, writing, estimating offsets from a bag, restamped copies
(docs/bags.md). Each name is imported at its first use (``evsync restamp`` loads no estimator)."""

from typing import TYPE_CHECKING

from evsync_ros.core.lazy import exports

if TYPE_CHECKING:
    from evsync_ros.bag.estimate import BagEstimate, estimate_bag, read_event_times
    from evsync_ros.bag.events import TopicReport
    from evsync_ros.bag.reader import BagReader
    from evsync_ros.bag.restamp import RestampReport, TopicCopy, load_offsets, restamp_bag
    from evsync_ros.bag.storage import Storage
    from evsync_ros.bag.writer import BagWriter

__all__ = [
    'BagEstimate',
    'BagReader',
    'BagWriter',
    'RestampReport',
    'Storage',
    'TopicCopy',
    'TopicReport',
    'estimate_bag',
    'load_offsets',
    'read_event_times',
    'restamp_bag',
]

__getattr__ = exports(__name__, {
    'BagEstimate': 'evsync_ros.bag.estimate',
    'TopicReport': 'evsync_ros.bag.events',
    'estimate_bag': 'evsync_ros.bag.estimate',
    'read_event_times': 'evsync_ros.bag.estimate',
    'BagReader': 'evsync_ros.bag.reader',
    'RestampReport': 'evsync_ros.bag.restamp',
    'TopicCopy': 'evsync_ros.bag.restamp',
    'load_offsets': 'evsync_ros.bag.restamp',
    'restamp_bag': 'evsync_ros.bag.restamp',
    'Storage': 'evsync_ros.bag.storage',
    'BagWriter': 'evsync_ros.bag.writer',
})
