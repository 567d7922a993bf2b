"""Shared test set-up: DDS kept on loopback in a domain of its own, and the real recordings."""

from __future__ import annotations

import os
import random
from pathlib import Path

import pytest

from evsync_testing.realdata import missing, real_data_dir

REPO = Path(__file__).resolve().parents[1]

# rclpy reads these when a context is initialised: keep discovery on this machine and away from
# any other test run that shares it.
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randint(1, 100)))

RECORDINGS = ('evt3_sqlite3', 'libcaer_cmp_mcap', 'evk4_hd', 'dvs128_stereo')


@pytest.fixture(scope='session')
def real_data() -> Path:
    """The folder of the real recordings; skipped with the reason where they are absent, except under
    CI (``CI`` set), which always has them."""
    path = real_data_dir()
    reason = missing(path, *RECORDINGS)
    if reason:
        if os.environ.get('CI'):
            pytest.fail(f'{reason}; CI always has them')
        pytest.skip(reason)
    return path
