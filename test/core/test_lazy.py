"""Imports put off to first use (``core.lazy``): a command loads only what it runs, and a module
loaded late is what an import would have given, as a package's attribute too."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def _loaded(code: str) -> dict:
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True, cwd=REPO)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_command_line_loads_no_estimator_simulator_or_plots_until_a_command_needs_them():
    got = _loaded('import json, sys; import evsync_ros.cli.main; '  # a module not yet run is a _LazyModule
                  'print(json.dumps({"run": sorted(m for m, v in sys.modules.items() '
                  'if type(v).__name__ != "_LazyModule")}))')
    heavy = ('evsync_ros.core.engine', 'evsync_ros.bag.estimate', 'evsync_ros.sim.', 'evsync_ros.cli.plots',
             'evsync_ros.core.paper', 'evsync_ros.core.refined', 'matplotlib')
    assert 'evsync_ros.bag.restamp' in got['run']
    assert not [m for m in got['run'] if m.startswith(heavy)]


def test_a_module_loaded_late_is_its_packages_attribute_and_works():
    got = _loaded(
        'import json, sys; import evsync_ros.cli.main, evsync_ros.cli.bagopts as cli; '
        'import evsync_ros.bag, evsync_ros.core; '
        'late = "evsync_ros.bag.estimate" in sys.modules; '
        'same = evsync_ros.bag.estimate is sys.modules["evsync_ros.bag.estimate"] is cli.estimate; '
        'works = callable(evsync_ros.bag.estimate.estimate_bag) and evsync_ros.core.paper.PaperParams().window_ns > 0; '
        'names = all(getattr(evsync_ros.core, n) is not None for n in evsync_ros.core.__all__) and '
        'all(getattr(evsync_ros.bag, n) is not None for n in evsync_ros.bag.__all__); '
        'print(json.dumps({"late": late, "same": same, "works": works, "names": names}))')
    assert got == {'late': True, 'same': True, 'works': True, 'names': True}
