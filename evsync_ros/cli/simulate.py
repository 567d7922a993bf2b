"""evsync simulate OUT: a simulated rig (per-pixel simulator, presets) as a bag with its ground truth."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from evsync_ros.bag import ros1
from evsync_ros.bag.writer import ROS1
from evsync_ros.cli.command import Arguments, Command, Exit
from evsync_ros.cli.tables import format_seconds
from evsync_ros.core import lazy

if TYPE_CHECKING:
    from evsync_ros.sim import pixelsim, simbag
else:  # loaded when a rig is simulated
    pixelsim = lazy.module('evsync_ros.sim.pixelsim')
    simbag = lazy.module('evsync_ros.sim.simbag')

__all__ = ['COMMAND']


def declare(a: Arguments) -> None:
    a.add('out', help='bag directory to create (must not exist); a name ending in .bag: a ROS 1 bag')
    a.add('--preset', choices=pixelsim.PRESETS, default='mixed-models')
    a.add('--seed', type=int, default=0)
    a.add('--duration', type=float, help='seconds of world time (default 30; 60 for drift)')
    a.add('--storage', choices=('sqlite3', 'mcap'), default='sqlite3', help='rosbag2 storage (default sqlite3)')
    a.add('--truth', help='ground-truth JSON path (default OUT.truth.json)')
    a.add('--imu-hz', type=float, default=0.0,
          help="also each camera's IMU at this rate, on <namespace>/imu (default 0: none)")
    a.add('--speed', type=float, metavar='PX_S',
          help="typical edge speed in the reference camera's pixels per second (default: the preset's)")
    a.add('--make', metavar='KEY=VALUE,...',
          help='every camera but the reference of another make: contrast, lowpass-us, refractory-us, '
               'noise-hz (e.g. contrast=0.30,lowpass-us=800)')
    a.add('--triggers', type=float, default=0.0, metavar='HZ',
          help="a pulse train at HZ wired to every camera's trigger input (default 0: none)")


def run(args: argparse.Namespace) -> int:
    rig = pixelsim.preset(args.preset, seed=args.seed, duration_s=args.duration, speed_px_s=args.speed,
                          make=pixelsim.parse_make(args.make) if args.make else None, triggers_hz=args.triggers)
    storage = ROS1 if ros1.is_ros1(args.out) else args.storage
    truth = simbag.write_rig(rig, pixelsim.simulate(rig, imu_hz=args.imu_hz), args.out, storage=storage,
                             truth=args.truth)
    for cam in truth['cameras']:
        print(f'{cam["topic"]:<20} {cam["encoding"]:<5} {cam["events"]:>10,} events  '
              f'offset {format_seconds(cam["offset_ns"])} s  '
              f'skew {cam["skew_ppm"]:+.2f} ppm')
    print(f'wrote {args.out} and {args.truth or args.out + ".truth.json"}')
    return Exit.DONE


COMMAND = Command(name='simulate', help='simulate a rig into a rosbag2 with a ground-truth JSON beside it',
                  declare=declare, run=run)
