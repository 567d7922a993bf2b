"""A rig's envelope latencies measured against trigger edges: what ``evsync verify --save-latencies``
writes and ``--latencies`` (the node's ``latencies_file``) reads (docs/triggers.md, "Calibrating")."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from evsync_ros.core.errors import ParameterError
from evsync_ros.core.triggers import Verdict, Verified

__all__ = ['FORMAT', 'Latencies', 'calibrated', 'combined']

FORMAT = 'evsync-latencies/1'
"""The file's ``format``: a reader refuses any other."""


@dataclass(frozen=True)
class Latencies:
    """Each camera's envelope latency (ns) relative to the calibration's reference (its own 0), with
    its standard error, and how the rig looked while it was measured."""

    reference: str
    latencies_ns: dict[str, int]
    se_ns: dict[str, float]
    measured: dict[str, Any] = field(default_factory=dict)

    def as_json(self) -> dict[str, Any]:
        return {'format': FORMAT, 'reference': self.reference, 'latencies_ns': dict(self.latencies_ns),
                'se_ns': dict(self.se_ns), 'measured': self.measured}

    def save(self, path: str | Path) -> Path:
        """Write it as JSON at ``path`` (whole or not at all: through a file beside it)."""
        path = Path(path)
        part = path.with_name(f'.{path.name}.partial')
        part.write_text(json.dumps(self.as_json(), indent=1) + '\n')
        part.replace(path)
        return path

    @classmethod
    def load(cls, path: str | Path) -> Latencies:
        """Read a file ``save`` wrote; ParameterError naming it when it is not one."""
        try:
            doc = json.loads(Path(path).read_text())
        except (OSError, ValueError) as exc:
            raise ParameterError(f'{path}: cannot read the latencies file: {exc}') from exc
        if not isinstance(doc, dict) or doc.get('format') != FORMAT:
            raise ParameterError(f'{path}: not a latencies file ({FORMAT}, as evsync verify --save-latencies '
                                 'writes)')
        values = doc.get('latencies_ns')
        if not isinstance(values, dict) or not all(isinstance(v, int) and abs(v) <= 1_000_000_000
                                                   for v in values.values()):
            raise ParameterError(f'{path}: latencies_ns must map topics to integer ns within +-1 s')
        return cls(str(doc.get('reference', '')), {str(k): int(v) for k, v in values.items()},
                   {str(k): float(v) for k, v in (doc.get('se_ns') or {}).items()}, dict(doc.get('measured') or {}))


def calibrated(results: Sequence[Verified], *, reference: str, measured: Mapping[str, Any]) -> Latencies:
    """The latencies ``results`` measured: each verified camera's, minus the signed mean of its
    windows' errors against the edges (the estimate's own error where it has no agreeing window),
    with the mean's standard error; the reference's 0."""
    lat, se = {reference: 0}, {reference: 0.0}
    for v in results:
        if v.verdict is not Verdict.VERIFIED or v.error_ns is None:
            continue
        e = v.window_errors_ns
        if len(e) >= 2:
            mean = sum(e) / len(e)
            sd = math.sqrt(sum((x - mean) ** 2 for x in e) / (len(e) - 1))
            lat[v.topic], se[v.topic] = -round(mean), sd / math.sqrt(len(e))
        else:
            lat[v.topic], se[v.topic] = -round(v.error_ns), float(v.stated_ns or math.nan)
    when = datetime.now(timezone.utc).isoformat(timespec='seconds')
    return Latencies(reference, lat, se, {'written_utc': when, **measured})


def combined(file: Latencies | None, given: Mapping[str, int], *, source: str, given_by: str = '--latency-us'
             ) -> dict[str, int]:
    """A file's latencies and those given one by one (``given_by``); ParameterError for a topic in both."""
    known = dict(file.latencies_ns) if file is not None else {}
    twice = sorted(set(known) & set(given))
    if twice:
        raise ParameterError(f'{", ".join(twice)}: a latency in {source} and one given by {given_by}; give each '
                             'camera one')
    return {**known, **given}
