"""Every library the package imports is declared where ROS and pip look for it: ``package.xml`` (what
rosdep installs for colcon) and ``setup.py`` (what pip installs). An import nobody declared works here
and fails on a user's machine (issue 24: ruamel.yaml was imported and declared nowhere)."""

from __future__ import annotations

import ast
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OWN = {'evsync_ros', 'msg_adapters'}

DECLARED_AS = {
    # top-level module: (package.xml key and the tags it may be under, pip distribution or None for ROS-only)
    'numpy': ('python3-numpy', 'numpy'),
    'rosbags': ('python3-rosbags', 'rosbags'),
    'ruamel': ('python3-ruamel.yaml', 'ruamel.yaml'),
    'lz4': ('python3-lz4', 'lz4'),
    'matplotlib': ('python3-matplotlib', 'matplotlib'),
    'hypothesis': ('python3-hypothesis', 'hypothesis'),
    'ament_index_python': ('ament_index_python', None),
    'rclpy': ('rclpy', None),
    'rcl_interfaces': ('rcl_interfaces', None),
    'std_msgs': ('std_msgs', None),
    'sensor_msgs': ('sensor_msgs', None),
    'diagnostic_msgs': ('diagnostic_msgs', None),
    'builtin_interfaces': ('builtin_interfaces', None),
    'std_srvs': ('std_srvs', None),
    'rosgraph_msgs': ('rosgraph_msgs', None),
    'launch': ('launch', None),
    'launch_ros': ('launch_ros', None),
}
"""ROS packages come from the ROS install (rosdep), not from pip: ``None``."""


def imported_modules() -> dict[str, set[str]]:
    """{top-level module: files importing it} over the installed packages' sources and launch files."""
    found: dict[str, set[str]] = {}
    for root in (*OWN, 'launch'):
        for path in (REPO / root).rglob('*.py'):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                names: list[str] = []
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                for name in names:
                    top = name.split('.')[0]
                    if top not in OWN and top not in sys.stdlib_module_names and top != '__future__':
                        found.setdefault(top, set()).add(str(path.relative_to(REPO)))
    return found


def package_xml_keys() -> set[str]:
    root = ET.parse(REPO / 'package.xml').getroot()
    tags = ('depend', 'exec_depend', 'build_depend', 'test_depend')
    return {e.text.strip() for tag in tags for e in root.iter(tag) if e.text}


def setup_requirements() -> set[str]:
    """Distribution names in setup.py's install_requires and extras_require (read from the source,
    without running it)."""
    tree = ast.parse((REPO / 'setup.py').read_text())
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg in ('install_requires', 'extras_require'):
            for const in ast.walk(node.value):
                if isinstance(const, ast.Constant) and isinstance(const.value, str):
                    names.add(re.split(r'[<>=!~; \[]', const.value)[0])
    return names


def test_every_imported_library_is_declared_in_package_xml_and_setup_py():
    keys, requirements = package_xml_keys(), setup_requirements()
    problems = []
    for module, files in sorted(imported_modules().items()):
        if module not in DECLARED_AS:
            problems.append(f'{module} (imported by {sorted(files)[0]}) is not in DECLARED_AS: say where it comes from')
            continue
        key, dist = DECLARED_AS[module]
        if key not in keys:
            problems.append(f'{module} (imported by {sorted(files)[0]}): package.xml does not declare {key}')
        if dist is not None and dist not in requirements:
            problems.append(f'{module} (imported by {sorted(files)[0]}): setup.py does not require {dist}')
    assert not problems, '\n'.join(problems)


def test_the_scan_sees_what_the_package_imports():
    """The check above cannot pass by seeing nothing: the libraries every layer stands on are found."""
    found = imported_modules()
    assert {'numpy', 'rosbags', 'rclpy', 'ruamel', 'launch_ros'} <= set(found), sorted(found)
