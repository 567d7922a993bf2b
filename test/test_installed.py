"""What an install holds: the package (``evsync_ros``, ``msg_adapters``) and not the helpers the tests,
benchmarks and studies share (``evsync_testing``), which stay in the repository as a ROS package's test
helpers do. Checked on what setup.py hands setuptools (what colcon and pip install), on a wheel pip
builds from the sources, and on the sources: no installed module may import a helper, or the
installed package would fail where the repository is absent."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

from test_launch import setup_kwargs  # type: ignore[import-not-found]  # test/test_launch.py, beside this file

REPO = Path(__file__).resolve().parents[1]
INSTALLED = ('evsync_ros', 'msg_adapters')
HELPERS = 'evsync_testing'


def is_helper(name: str) -> bool:
    """A module or package of the test helpers, where they are now or where they were (evsync_ros.testing)."""
    parts = name.split('.')
    return parts[0] == HELPERS or parts[:2] == ['evsync_ros', 'testing']


def source_packages() -> set[str]:
    """Every package (a folder with __init__.py) under the installed roots."""
    inits = [p for root in INSTALLED for p in (REPO / root).rglob('__init__.py')]
    return {'.'.join(p.parent.relative_to(REPO).parts) for p in inits}


def test_setup_installs_every_package_of_the_core_and_none_of_the_helpers():
    packages = set(setup_kwargs()['packages'])
    assert {'evsync_ros', 'evsync_ros.core', 'evsync_ros.core.engine', 'msg_adapters'} <= packages, sorted(packages)
    assert not [p for p in packages if is_helper(p)], sorted(packages)
    assert source_packages() == packages, sorted(source_packages() ^ packages)


def test_the_wheel_pip_builds_holds_the_package_and_not_the_helpers(tmp_path):
    src = tmp_path / 'src'
    # the sources as a clone has them, built outside the repository (a build writes build/ and egg-info)
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(
        '.git', '.venv', 'build', 'install', 'log', '*.egg-info', '__pycache__', '.pytest_cache', '*.so'))
    subprocess.run([sys.executable, '-m', 'pip', 'wheel', '--quiet', '--no-deps', '--no-build-isolation', '--no-index',
                    '--disable-pip-version-check', '--wheel-dir', str(tmp_path / 'dist'), str(src)],
                   check=True, capture_output=True, text=True)
    (wheel,) = (tmp_path / 'dist').glob('evsync_ros-*.whl')
    names = zipfile.ZipFile(wheel).namelist()
    modules = {n for n in names if n.endswith('.py')}
    assert {'evsync_ros/core/engine/engine.py', 'evsync_ros/cli/main.py', 'evsync_ros/ros/node.py',
            'msg_adapters/evt3.py', 'evsync_ros/py.typed'} <= set(names), sorted(names)
    assert [n for n in names if n.startswith('msg_adapters/_kernels') and n.endswith('.so')], sorted(names)
    shipped = {n.removesuffix('.py').removesuffix('/__init__').replace('/', '.') for n in modules}
    assert not [m for m in shipped if is_helper(m)], sorted(shipped)
    # every module of the package's sources is in it
    expected = {str(p.relative_to(REPO)) for root in INSTALLED for p in (REPO / root).rglob('*.py')}
    assert expected <= modules, sorted(expected - modules)


def test_no_installed_module_imports_the_helpers():
    bad = []
    for root in INSTALLED:
        for path in sorted((REPO / root).rglob('*.py')):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                names: list[str] = []
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    # `from evsync_ros import testing` names the helpers in its alias
                    names = [node.module] + [f'{node.module}.{a.name}' for a in node.names]
                helpers = [n for n in names if is_helper(n)]
                if helpers:
                    bad.append(f'{path.relative_to(REPO)} imports {helpers[0]}')
    assert not bad, '\n'.join(bad)
