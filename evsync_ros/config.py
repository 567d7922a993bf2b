"""Parameter files in ROS 2 form: ``<node>: {ros__parameters: {...}}``, read without rclpy."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ruamel.yaml import YAML, YAMLError

from .errors import ParameterError
from .paper import PaperParams

#: Estimator parameters as named in the YAML, and their PaperParams field and unit.
PAPER_KEYS = {
    'tau_ms': ('tau_ns', 1e6),
    'window_s': ('window_ns', 1e9),
    'epsilon': ('epsilon', None),
    'percentile': ('percentile', None),
    'min_overlap': ('min_overlap', None),
}


def load_ros_parameters(path: str | Path, *, node: str = 'evsync') -> dict[str, Any]:
    """The ``ros__parameters`` of ``node`` (or of the wildcard ``/**``) in a parameter file."""
    path = Path(path)
    try:
        doc = YAML(typ='safe').load(path.read_text())
    except (OSError, YAMLError) as exc:
        raise ParameterError(f'{path}: cannot read parameter file: {exc}') from exc
    for key in (node, f'/{node}', '/**'):
        section = (doc or {}).get(key) if isinstance(doc, dict) else None
        if isinstance(section, dict) and isinstance(section.get('ros__parameters'), dict):
            return dict(section['ros__parameters'])
    raise ParameterError(f'{path}: no {node}: ros__parameters section')


def paper_params_from(values: dict[str, Any], *, source: str) -> PaperParams:
    """PaperParams from YAML-named values; unknown estimator keys are ignored by design."""
    kwargs: dict[str, Any] = {}
    for key, (field, scale) in PAPER_KEYS.items():
        if key not in values:
            continue
        value = values[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f'{source}: {key} must be a number, got {value!r}')
        kwargs[field] = round(value * scale) if scale else float(value)
    return PaperParams(**kwargs)
