"""Shared test set-up: DDS kept on loopback in a domain of its own, and the real recordings."""

from __future__ import annotations

import os
import random
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# rclpy reads these when a context is initialised: keep discovery on this machine and away from
# any other test run that shares it.
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randint(1, 100)))


def real_data_dir() -> Path:
    """Where the real recordings are: $EVSYNC_REAL_DATA, else ../shared/data/real beside the repo."""
    env = os.environ.get('EVSYNC_REAL_DATA')
    return Path(env) if env else REPO.parent / 'shared' / 'data' / 'real'


@pytest.fixture(scope='session')
def real_data() -> Path:
    path = real_data_dir()
    if not (path / 'evt3_sqlite3').is_dir() or not (path / 'libcaer_cmp_mcap').is_dir():
        reason = (f'real recordings not found at {path} '
                  '(put shared/ beside the repository or set EVSYNC_REAL_DATA)')
        if os.environ.get('CI'):
            pytest.fail(f'{reason}; CI always has them')
        pytest.skip(reason)
    return path
