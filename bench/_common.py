"""Shared bits of the benchmark scripts: where the real recordings are."""

from __future__ import annotations

import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def real_data_dir() -> Path:
    path = Path(os.environ.get('EVSYNC_REAL_DATA') or REPO.parent / 'shared' / 'data' / 'real')
    if not (path / 'evt3_sqlite3').is_dir():
        sys.exit(f'real recordings not found at {path} (put shared/ beside the repository or set EVSYNC_REAL_DATA)')
    return path
