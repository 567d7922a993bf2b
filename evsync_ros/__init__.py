"""evsync_ros: synchronise event cameras in software by aligning their event densities.

Layers: the estimation core (``core``) imports numpy only and works on int64-nanosecond arrays;
``msg_adapters`` turns message bytes into such arrays; the CLI (``cli``), the bag tools (``bag``,
rosbags) and the node (``ros``, rclpy) are thin front ends over both; ``sim`` simulates rigs.

Sign convention everywhere: a camera's *offset* is what you add to its times to express them on
the reference camera's timeline; the reference has offset 0.
"""

import os as _os

# One BLAS thread. The estimator's BLAS calls (dot products of a few thousand values) gain nothing
# from more, and OpenBLAS's pool, once woken, spins on every core for a while after each call: CPU
# a node running beside camera drivers cannot spare. Effective when evsync_ros is imported before
# numpy, as the evsync and evsync_node commands do; OPENBLAS_NUM_THREADS set by the user wins.
_os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

__version__ = '1.0.0'
