"""The estimation core: numpy only, int64-nanosecond event times on each camera's own timeline.

Densities and bins, clock corrections, the paper's method, the refined method, streaming and
online tracking. Nothing here imports rclpy, rosbags or the message adapters.
"""
