"""The layers hold: the core imports numpy only, msg_adapters nothing of evsync_ros, and no package
imports another that sits above it. Checked in fresh interpreters (what an import really loads) and
on the source (what a module names), so that a lazy import inside a function is caught too."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

ALLOWED = {
    # package: the project packages its modules may import (besides its own)
    'evsync_ros.core': set(),
    'msg_adapters': set(),
    'evsync_ros.runtime': {'evsync_ros.core', 'evsync_ros.errors', 'evsync_ros.lifetime'},
    'evsync_ros.sim': {'evsync_ros.core', 'evsync_ros.bag', 'msg_adapters', 'evsync_ros.errors'},
    'evsync_ros.bag': {'evsync_ros.core', 'msg_adapters', 'evsync_ros.errors', 'evsync_ros.lifetime'},
    'evsync_ros.ros': {'evsync_ros.core', 'evsync_ros.bag', 'evsync_ros.runtime', 'msg_adapters', 'evsync_ros.errors',
                       'evsync_ros.lifetime'},
    'evsync_ros.cli': {'evsync_ros.core', 'evsync_ros.bag', 'evsync_ros.sim', 'evsync_ros.ros', 'evsync_ros.runtime',
                       'msg_adapters',
                       'evsync_ros.errors', 'evsync_ros.lifetime', 'evsync_ros'},
}


def loaded_after(module: str) -> list[str]:
    code = f'import json, sys; import {module}; print(json.dumps(sorted(sys.modules)))'
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True, cwd=REPO)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize('module', ['evsync_ros.core', 'evsync_ros.core.refined', 'evsync_ros.core.engine',
                                    'evsync_ros.core.engine', 'evsync_ros.core.engine.arrays',
                                    'evsync_ros.core.results'])
def test_the_core_loads_neither_rclpy_nor_rosbags_nor_the_adapters(module):
    loaded = loaded_after(module)
    for other in ('rclpy', 'rosbags', 'msg_adapters', 'ruamel', 'matplotlib', 'evsync_ros.bag', 'evsync_ros.ros',
                  'evsync_ros.runtime', 'subprocess'):
        assert not [m for m in loaded if m == other or m.startswith(other + '.')], f'{module} loads {other}'


def test_msg_adapters_load_nothing_of_evsync_ros():
    loaded = loaded_after('msg_adapters.registry')
    assert not [m for m in loaded if m.startswith('evsync_ros')]


def _project_imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
    return {n for n in names if n.split('.')[0] in ('evsync_ros', 'msg_adapters')}


@pytest.mark.parametrize('package', sorted(ALLOWED))
def test_no_module_imports_a_package_above_its_own(package):
    folder = REPO / package.replace('.', '/')
    bad = []
    for path in sorted(folder.glob('*.py')):
        for name in _project_imports(path):
            if name == package or name.startswith(package + '.'):
                continue
            if not any(name == a or name.startswith(a + '.') for a in ALLOWED[package]):
                bad.append(f'{path.relative_to(REPO)} imports {name}')
    assert not bad, '\n'.join(bad)
