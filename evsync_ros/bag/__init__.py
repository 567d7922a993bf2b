"""Recorded bags (rosbags): reading, writing, estimating offsets from a bag, restamped copies
(docs/bags.md)."""

from evsync_ros.bag.estimate import BagEstimate, TopicReport, estimate_bag, read_event_times
from evsync_ros.bag.reader import BagReader
from evsync_ros.bag.restamp import RestampReport, TopicCopy, load_offsets, restamp_bag
from evsync_ros.bag.writer import BagWriter

__all__ = [
    'BagEstimate',
    'BagReader',
    'BagWriter',
    'RestampReport',
    'TopicCopy',
    'TopicReport',
    'estimate_bag',
    'load_offsets',
    'read_event_times',
    'restamp_bag',
]
