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
    'rosbags': ('python3-rosbags-pip', 'rosbags'),
    'ruamel': ('python3-ruamel.yaml', 'ruamel.yaml'),
    'lz4': ('python3-rosbags-pip', 'lz4'),  # rosbags' own dependency: pip installs it with rosbags
    'apsw': ('python3-rosbags-pip', 'apsw'),  # rosbags' own sqlite3 binding, as lz4
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

ROSDEP_KEYS = {'python3-numpy', 'python3-rosbags-pip', 'python3-ruamel.yaml', 'python3-matplotlib', 'python3-pytest',
               'python3-hypothesis', 'python3-dev'}
"""Keys of rosdistro's rosdep/python.yaml this package uses, each checked there (ros/rosdistro at
8468e88, 2026-08-22). Not there: python3-rosbags (the key is python3-rosbags-pip), python3-lz4."""
JAZZY_PACKAGES = {'rclpy', 'std_msgs', 'std_srvs', 'sensor_msgs', 'diagnostic_msgs', 'builtin_interfaces',
                  'rcl_interfaces', 'rosgraph_msgs', 'event_camera_msgs', 'ament_index_python', 'launch', 'launch_ros',
                  'metavision_driver', 'libcaer_driver'}
"""ROS packages released in Jazzy that this package may name (rosdistro jazzy/distribution.yaml, same
commit). Not released in any ROS 2 distribution: dvs_msgs, prophesee_event_msgs."""


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


def test_every_package_xml_key_resolves_with_rosdep():
    """``rosdep install`` stops at a key it cannot resolve: every one here is a rosdep key or a ROS
    package released in Jazzy (issue 39: python3-rosbags is no key)."""
    unresolved = sorted(package_xml_keys() - ROSDEP_KEYS - JAZZY_PACKAGES)
    assert not unresolved, f'package.xml keys rosdep cannot resolve: {unresolved}'


def test_the_camera_drivers_are_not_forced_on_every_user():
    """The example launch's drivers (one per camera make) and the EventArray message packages are
    documented, not declared: a rig of one make needs neither the other's driver nor its messages."""
    keys = package_xml_keys()
    assert not keys & {'metavision_driver', 'libcaer_driver', 'dvs_msgs', 'prophesee_event_msgs'}


def test_one_version_everywhere_it_is_written():
    """The version a restamped bag records (the installed distribution's) is the one package.xml,
    setup.py and ``evsync_ros.__version__`` say."""
    import importlib.metadata

    import evsync_ros

    xml = ET.parse(REPO / 'package.xml').getroot().findtext('version')
    setup = re.search(r"version='([^']+)'", (REPO / 'setup.py').read_text())
    assert setup is not None
    assert evsync_ros.__version__ == xml == setup.group(1) == importlib.metadata.version('evsync_ros')
