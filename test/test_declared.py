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

ROSDEP_RULES: dict[str, dict[str, object]] = {
    'python3-numpy': {'debian': ['python3-numpy'], 'ubuntu': ['python3-numpy']},
    'python3-rosbags-pip': {'debian': {'pip': {'packages': ['rosbags']}}, 'ubuntu': {'pip': {'packages': ['rosbags']}}},
    'python3-ruamel.yaml': {'debian': {'buster': ['python3-ruamel.yaml'], 'stretch': ['python3-ruamel.yaml']},
                            'ubuntu': ['python3-ruamel.yaml']},
    'python3-matplotlib': {'debian': ['python3-matplotlib'], 'ubuntu': ['python3-matplotlib']},
    'python3-pytest': {'debian': ['python3-pytest'], 'ubuntu': ['python3-pytest']},
    'python3-hypothesis': {'debian': ['python3-hypothesis'], 'ubuntu': ['python3-hypothesis']},
    'python3-dev': {'debian': ['python3-dev'], 'ubuntu': ['python3-dev']},
}
"""The Debian and Ubuntu rules of the rosdep keys this package uses, as rosdistro's rosdep/python.yaml
has them (ros/rosdistro at 8468e88, 2026-08-22; the other platforms' left out). Not there:
python3-rosbags (the key is python3-rosbags-pip), python3-lz4."""
ROSDEP_KEYS = set(ROSDEP_RULES)
PLATFORMS = {'ubuntu': 'noble', 'debian': 'bookworm'}
"""Where this package is installed with rosdep: Jazzy's Tier 1 platform, and its Debian one."""
PEP668_PYTHON = {'noble': (3, 12), 'bookworm': (3, 11)}
"""Each platform's system Python, externally managed (PEP 668) on both: a pip rule needs a documented way."""
KNOWN_GAPS = {('python3-ruamel.yaml', 'bookworm'): '--skip-keys python3-ruamel.yaml'}
"""Keys rosdistro has no rule for on a platform, with what docs/development.md says to do there."""
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


def resolve(key: str, os_name: str, codename: str) -> tuple[str, list[str]] | None:
    """What rosdep installs for ``key`` on ``os_name`` ``codename``, from ``ROSDEP_RULES`` as rosdep
    reads a rule: a list of packages for every version, or one list per codename (``*`` for the
    rest), each either packages of the OS's installer or an installer's own ({'pip': {'packages':
    [...]}}); None when there is no rule (rosdep stops there)."""
    rule = ROSDEP_RULES[key].get(os_name)
    if isinstance(rule, dict) and 'pip' not in rule:
        rule = rule.get(codename, rule.get('*'))
    if rule is None:
        return None
    if isinstance(rule, dict):
        return 'pip', list(rule['pip']['packages'])
    return 'apt', list(rule)  # type: ignore[call-overload]


def test_every_rosdep_key_resolves_on_noble_and_bookworm_or_the_docs_say_how():
    """Issue 52: rosdep install stops at a key with no rule for the platform; each such key, on each
    platform, is one docs/development.md gives the way around."""
    doc = (REPO / 'docs' / 'development.md').read_text()
    for key in sorted(package_xml_keys() & ROSDEP_KEYS):
        for os_name, codename in PLATFORMS.items():
            found = resolve(key, os_name, codename)
            gap = KNOWN_GAPS.get((key, codename))
            if found is None:
                assert gap is not None, f'{key} has no rosdep rule on {os_name} {codename} and nothing says so'
                assert gap in doc, f'docs/development.md does not say {gap!r} for {key} on {codename}'
            else:
                assert gap is None, f'{key} resolves on {codename} now ({found}): drop it from KNOWN_GAPS'
    assert resolve('python3-ruamel.yaml', 'debian', 'bookworm') is None  # as rosdistro has it
    assert resolve('python3-ruamel.yaml', 'ubuntu', 'noble') == ('apt', ['python3-ruamel.yaml'])


def test_a_pip_key_under_pep_668_comes_with_the_documented_way():
    """Both platforms' system Pythons are externally managed: rosdep's pip install fails there unless
    PIP_BREAK_SYSTEM_PACKAGES (rosdep's documented way) or a venv is used, and the docs' command,
    as written, sets it."""
    doc = (REPO / 'docs' / 'development.md').read_text()
    pip_keys = [k for k in package_xml_keys() & ROSDEP_KEYS
                if any((resolve(k, o, c) or ('', []))[0] == 'pip' for o, c in PLATFORMS.items())]
    assert pip_keys == ['python3-rosbags-pip']
    assert all(PEP668_PYTHON[c] >= (3, 11) for c in PLATFORMS.values())
    commands = [line for line in doc.splitlines() if 'rosdep install' in line and not line.startswith('`')]
    assert commands and all('PIP_BREAK_SYSTEM_PACKAGES=1 rosdep install' in line or '--skip-keys python3-rosbags-pip'
                            in line for line in commands), commands
    assert 'sudo rosdep init' in doc and 'rosdep update' in doc  # rosdep install fails on a machine without them
    assert '--system-site-packages' in doc  # the venv way, for who keeps pip out of the system Python


def test_licence_files_say_what_the_package_xml_declare():
    """REP 2004: a LICENSE, the one package.xml and setup.py name (Apache-2.0, the full text); each
    bundled interface package under its upstream licence, with the upstream's licence file."""
    text = (REPO / 'LICENSE').read_text()
    assert 'Apache License' in text and 'Version 2.0, January 2004' in text and 'END OF TERMS AND CONDITIONS' in text
    assert len(text.splitlines()) == 202  # the whole text, its appendix included
    root = ET.parse(REPO / 'package.xml').getroot()
    assert root.findtext('license') == 'Apache-2.0' and "license='Apache-2.0'" in (REPO / 'setup.py').read_text()
    upstream = {'event_camera_msgs': 'Apache-2.0', 'prophesee_event_msgs': 'Apache-2.0', 'dvs_msgs': 'MIT'}
    for pkg, licence in upstream.items():
        xml = ET.parse(REPO / 'interfaces' / pkg / 'package.xml').getroot()
        assert xml.findtext('license') == licence, pkg
        own = (REPO / 'interfaces' / pkg / 'LICENSE').read_text()
        assert ('MIT License' in own) == (licence == 'MIT') and ('Apache License' in own) == (licence == 'Apache-2.0')
        assert xml.find("url[@type='repository']") is not None, pkg
    readme = (REPO / 'README.md').read_text()
    assert 'Apache License 2.0' in readme and 'dvs_msgs MIT' in readme


def test_the_maintainer_is_no_example_address():
    addresses = [e.get('email', '') for p in [REPO / 'package.xml', *(REPO / 'interfaces').glob('*/package.xml')]
                 for e in ET.parse(p).getroot().iter('maintainer')]
    setup = re.search(r"maintainer_email='([^']+)'", (REPO / 'setup.py').read_text())
    assert setup is not None
    addresses.append(setup.group(1))
    reserved = ('example.org', 'example.com', 'example.net', '.example', '.invalid', '.test', '.localhost')
    for address in addresses:
        assert re.fullmatch(r'[\w.+-]+@[\w-]+(\.[\w-]+)+', address), address
        assert not address.endswith(reserved), address  # RFC 2606 names, never a mailbox
    assert len(set(addresses)) == 1


def test_the_changelog_is_in_the_ros_format_and_names_this_version():
    """CHANGELOG.rst as catkin_generate_changelog writes it: its title, then a section per version,
    newest first, ``X.Y.Z (YYYY-MM-DD)`` underlined with dashes, bullet lines in each."""
    lines = (REPO / 'CHANGELOG.rst').read_text().splitlines()
    assert lines[:3] == ['^' * 32, 'Changelog for package evsync_ros', '^' * 32]
    heads = [(i, m) for i, line in enumerate(lines)
             if (m := re.fullmatch(r'(\d+\.\d+\.\d+) \((\d{4}-\d{2}-\d{2})\)', line))]
    assert [m.group(1) for _, m in heads][:1] == [ET.parse(REPO / 'package.xml').getroot().findtext('version')]
    versions = [tuple(int(x) for x in m.group(1).split('.')) for _, m in heads]
    assert versions == sorted(versions, reverse=True) and len(versions) >= 2
    for k, (i, m) in enumerate(heads):
        assert lines[i + 1] == '-' * len(lines[i]), lines[i]
        section = lines[i + 2:heads[k + 1][0] if k + 1 < len(heads) else len(lines)]
        assert any(line.startswith('* ') for line in section), m.group(0)
