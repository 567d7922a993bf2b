"""The estimation core: numpy only, int64-nanosecond event times on each camera's own timeline.

Densities and bins, clock corrections, the result contract, the paper's method, the refined method,
streaming and online tracking (docs/method.md). Nothing here imports rclpy, rosbags or the message
adapters.
"""

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.engine.arrays import estimate_offset, estimate_offsets, estimate_rig, fit_camera
from evsync_ros.core.errors import EvsyncError, ParameterError, StreamError
from evsync_ros.core.online import OnlineParams, OnlineSync, State, Status
from evsync_ros.core.paper import PaperEstimate, PaperParams
from evsync_ros.core.refined import RefinedParams
from evsync_ros.core.results import METHODS, CameraFit, RigFit, WindowFit, load_rig

__all__ = [
    'METHODS',
    'CameraFit',
    'ClockCorrection',
    'EvsyncError',
    'OnlineParams',
    'OnlineSync',
    'PaperEstimate',
    'PaperParams',
    'ParameterError',
    'RefinedParams',
    'RigFit',
    'State',
    'Status',
    'StreamError',
    'WindowFit',
    'estimate_offset',
    'estimate_offsets',
    'estimate_rig',
    'fit_camera',
    'load_rig',
]
