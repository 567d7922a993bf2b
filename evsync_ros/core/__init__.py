"""The estimation core: numpy only, int64-nanosecond event times on each camera's own timeline.

Densities and bins, clock corrections, the result contract, the paper's method, the refined method,
streaming and online tracking (docs/method.md). Nothing here imports rclpy, rosbags or the message
adapters. Each name is imported at its first use (a restamp needs clocks, not the engine).
"""

from typing import TYPE_CHECKING

from evsync_ros.core.lazy import exports

if TYPE_CHECKING:
    from evsync_ros.core.clock import ClockCorrection
    from evsync_ros.core.engine import Engine, EngineParams, State, Status
    from evsync_ros.core.engine.arrays import estimate_offset, estimate_offsets, estimate_rig, fit_camera
    from evsync_ros.core.errors import EvsyncError, ParameterError, StreamError
    from evsync_ros.core.paper import PaperEstimate, PaperParams
    from evsync_ros.core.refined import RefinedParams
    from evsync_ros.core.results import METHODS, CameraFit, RigFit, WindowFit, load_rig

__all__ = [
    'METHODS',
    'CameraFit',
    'ClockCorrection',
    'Engine',
    'EngineParams',
    'EvsyncError',
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

__getattr__ = exports(__name__, {
    'ClockCorrection': 'evsync_ros.core.clock',
    'estimate_offset': 'evsync_ros.core.engine.arrays',
    'estimate_offsets': 'evsync_ros.core.engine.arrays',
    'estimate_rig': 'evsync_ros.core.engine.arrays',
    'fit_camera': 'evsync_ros.core.engine.arrays',
    'EvsyncError': 'evsync_ros.core.errors',
    'ParameterError': 'evsync_ros.core.errors',
    'StreamError': 'evsync_ros.core.errors',
    'Engine': 'evsync_ros.core.engine',
    'EngineParams': 'evsync_ros.core.engine',
    'State': 'evsync_ros.core.engine',
    'Status': 'evsync_ros.core.engine',
    'PaperEstimate': 'evsync_ros.core.paper',
    'PaperParams': 'evsync_ros.core.paper',
    'RefinedParams': 'evsync_ros.core.refined',
    'METHODS': 'evsync_ros.core.results',
    'CameraFit': 'evsync_ros.core.results',
    'RigFit': 'evsync_ros.core.results',
    'WindowFit': 'evsync_ros.core.results',
    'load_rig': 'evsync_ros.core.results',
})
