"""evsync_ros: synchronise event cameras in software by aligning their event densities.

Layers: the estimation core (``density``, ``paper``, ``rigsim``) imports numpy only and works on
int64-nanosecond arrays; ``msg_adapters`` turns message bytes into such arrays; the CLI, the
bag tools (rosbags) and the node (rclpy) are thin front ends over both.

Sign convention everywhere: a camera's *offset* is what you add to its times to express them on
the reference camera's timeline; the reference has offset 0.
"""

__version__ = '0.1.0'
