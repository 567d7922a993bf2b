"""The result contract: one window's fit, one camera's estimate, a rig's estimates, and their JSON.

numpy only. Every result is built with keyword arguments. ``RigFit.as_json`` writes, and
``RigFit.from_json`` reads, the object ``evsync estimate --json`` prints (a stable contract: fields
may be added, never changed):

    {"reference": TOPIC, "cameras": [{"topic", "offset_ns", "skew_ppm", "anchor_ns", "accepted",
                                      "cost", "confidence", "window_ns": [start, end]}]}

An event stamped t on a camera's timeline happened at
``t + offset_ns + skew_ppm * 1e-6 * (t - anchor_ns)`` on the reference's (``clock.ClockCorrection``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from evsync_ros.core.clock import ClockCorrection
from evsync_ros.core.errors import ParameterError, StreamError
from evsync_ros.core.host import HOST, HostFit

__all__ = ['METHODS', 'PRIORS', 'CameraFit', 'Method', 'Prior', 'PriorChoice', 'Reason', 'RigFit', 'WindowFit',
           'latency_deltas', 'load_rig']

class Method(str, Enum):
    """The estimator a rig is run with."""

    REFINED = 'refined'
    PAPER = 'paper'

    @classmethod
    def of(cls, value: object) -> Method:
        """``value`` as a method (StreamError naming the choices otherwise)."""
        try:
            return cls(value)
        except ValueError:
            raise StreamError(f"method must be one of {', '.join(METHODS)}, got {value!r}") from None


METHODS = tuple(m.value for m in Method)
"""The methods' names, as commands and parameters take them."""


class Prior(str, Enum):
    """What placed a camera's windows and centred their search (docs/method.md, "Record times")."""

    ARRIVAL = 'arrival'
    """When its messages arrived (a bag's record times, the node's clock), against the reference's."""
    EVENTS = 'events'
    """Its events alone: its first events against the reference's, then the line its windows agree on."""

    @classmethod
    def of(cls, value: object) -> Prior:
        """``value`` as a prior (ParameterError naming the choices otherwise)."""
        try:
            return cls(value)
        except ValueError:
            raise ParameterError(f"prior must be one of {', '.join(PRIORS)}, got {value!r}") from None


PRIORS = tuple(p.value for p in Prior)


class Reason(str, Enum):
    """The kind of a decision's reason (its text says more): what front ends decide on, never the text."""

    NONE = ''
    TOO_SHORT = 'too short'
    TOO_FLAT = 'too flat'
    QUIET_OUTSIDE = 'too flat outside'
    """Refused only for quiet windows outside the stretch where the agreeing ones lie."""
    DISAGREE = 'windows disagree'
    CHANCE = 'could be chance'
    CLOCK_STEP = 'clock step'
    AMBIGUOUS = 'ambiguous'
    UNCERTAIN = 'uncertain'
    EPSILON = 'min D not below epsilon'
    """The paper's loop accepted no window."""
    NOT_ON_HOST = 'not on host time'
    OTHER = 'other'
    """A reason of no kind above (text from elsewhere)."""

    @property
    def no_evidence(self) -> bool:
        """The decision has nothing to go on (no window, or none loud enough), rather than something
        against a line: a lock holds through it."""
        return self in (Reason.TOO_SHORT, Reason.TOO_FLAT, Reason.QUIET_OUTSIDE)

    @classmethod
    def of(cls, text: str) -> Reason:
        """The kind a reason's text begins with (text read back from JSON); NONE for ''."""
        found = [k for k in cls if k.value and text.startswith(k.value)]
        return max(found, key=lambda k: len(k.value), default=cls.NONE if not text else cls.OTHER)


class PriorChoice(str, Enum):
    """Which prior a user lets place the windows (``--prior``, the node's ``prior``)."""

    AUTO = 'auto'
    """Arrival times where they hold, else the events alone (``engine.evidence``)."""
    ARRIVAL = 'arrival'
    EVENTS = 'events'

_EMPTY: npt.NDArray[np.float64] = np.empty(0)
_EMPTY.flags.writeable = False


def _empty() -> npt.NDArray[np.float64]:
    return _EMPTY


@dataclass(frozen=True, kw_only=True)
class WindowFit:
    """One window of one camera against the reference (the refined method)."""

    ref_start_ns: int
    """Start of the window on the reference timeline."""
    offset_ns: int
    """Refined offset from this window (camera time + offset = reference time)."""
    peak: float
    """The coarse correlation at its maximum (NaN when the window could not be searched)."""
    confidence: float
    """The peak against its best rival, in [0, 1]."""
    accepted: bool
    """Whether the window agrees with the camera's accepted line (false until the camera is estimated)."""
    length_ns: int = 10_000_000_000
    """The window's length."""
    se_ns: float = math.inf
    """Standard error of ``offset_ns`` (a jackknife over the window's blocks); inf: no clear peak."""
    smooth_ns: int = 0
    """The smoothing the refinement kept."""
    candidates: tuple[tuple[int, float], ...] = ()
    """(offset, correlation) of the window's best coarse peaks, the best first."""
    refined: tuple[tuple[int, int, float], ...] = ()
    """(smoothing sigma, offset, standard error) of the refinement under each smoothing tried."""
    has_data: bool = True
    """Whether enough of the window had events of both cameras to be searched."""
    lags_ns: npt.NDArray[np.int64] | npt.NDArray[np.float64] = field(default_factory=_empty, repr=False)
    """Coarse lags searched (relative to the prior offset) ..."""
    ncc: npt.NDArray[np.float64] = field(default_factory=_empty, repr=False)
    """... and the NCC at each (NaN where the overlap was too small)."""
    prior_ns: int = 0
    """The offset the search was centred on."""
    ref_counts: npt.NDArray[np.float64] = field(default_factory=_empty, repr=False)
    """The reference's events per tau over [ref_start, ref_start + T) ..."""
    cam_counts: npt.NDArray[np.float64] = field(default_factory=_empty, repr=False)
    """... and the camera's over the same span mapped by the prior, widened by S on both sides."""

    def light(self) -> WindowFit:
        """The same fit without its curve and counts (what a long stream keeps of most windows)."""
        return replace(self, lags_ns=_EMPTY, ncc=_EMPTY, ref_counts=_EMPTY, cam_counts=_EMPTY)


@dataclass(frozen=True, kw_only=True)
class CameraFit:
    """One camera's estimate against the reference: a camera entry of the contract."""

    topic: str
    offset_ns: int
    skew_ppm: float
    anchor_ns: int
    accepted: bool
    cost: float
    """1 - the correlation peak (refined), or min D (paper); NaN when the source did not say."""
    confidence: float
    window_ns: tuple[int, int]
    """Span of the reference timeline the estimate comes from."""
    uncertainty_ns: float | None = None
    """Standard error of the offset at the anchor (systematic part included); None: not known."""
    skew_uncertainty_ppm: float | None = None
    """Standard error of the skew; None: no skew fitted."""
    reason: str = ''
    """Why the estimate was not accepted ('' when it was)."""
    kind: Reason = Reason.NONE
    """The kind of ``reason`` (not part of the JSON, whose reason text begins with it)."""
    windows_agreeing: int = 0
    """Windows that agree on the estimate."""
    windows_total: int = 0
    """Windows searched."""
    spread_ns: float | None = None
    """The agreeing windows' weighted spread about the line, a part of ``uncertainty_ns`` (refined,
    accepted; ``agreement.spread``)."""
    windows: tuple[WindowFit, ...] = field(default=(), repr=False)
    """The windows behind the estimate (refined; not part of the JSON)."""
    stretch_ns: tuple[int, int] | None = field(default=None, repr=False)
    """Refused only for quiet windows outside this span of the reference timeline, where the agreeing
    windows lie (refined; ``agreement.Agreement.quiet_outside``; not part of the JSON)."""
    step: tuple[int, int] | None = field(default=None, repr=False)
    """Refused for a clock step: the first and last of the run of ``windows`` off the line (refined;
    ``agreement.Agreement.step``; not part of the JSON)."""
    prior: Prior | None = None
    """What placed its windows (None: the reference, or not said)."""
    prior_reason: str = ''
    """Why that prior, in words ('' where there was no choice to make)."""
    edges: int = 0
    """Trigger edges its line was taken from (``triggers.by_edges``; 0: the density's own line)."""
    density_offset_ns: int | None = None
    """With ``edges``: the density decision's offset, before the edges placed it."""
    tied_to: str = ''
    """With ``edges``: the camera whose edges they were tied to, where not the reference
    (``triggers.tie``: the reference had none)."""

    @classmethod
    def reference_entry(cls, topic: str, *, start_ns: int, window_ns: int) -> CameraFit:
        """The reference's own entry: offset 0, accepted, over its first window."""
        return cls(topic=topic, offset_ns=0, skew_ppm=0.0, anchor_ns=0, accepted=True, cost=0.0, confidence=1.0,
                   window_ns=(start_ns, start_ns + window_ns), uncertainty_ns=0.0, spread_ns=0.0)

    def uncertainty_at(self, t_ns: int) -> float | None:
        """The standard error of the offset this estimate gives at camera time ``t_ns``: the offset's
        at the anchor and the skew's over the distance from it, in quadrature (None: not known)."""
        if self.uncertainty_ns is None:
            return None
        return math.hypot(self.uncertainty_ns, (self.skew_uncertainty_ppm or 0.0) * 1e-6 * (t_ns - self.anchor_ns))

    @property
    def correction(self) -> ClockCorrection:
        """This estimate as the correction that maps the camera's times onto the reference's."""
        return ClockCorrection(offset_ns=self.offset_ns, skew_ppm=self.skew_ppm, anchor_ns=self.anchor_ns)

    def as_json(self) -> dict[str, Any]:
        """This camera's entry of the contract, fields in the contract's order."""
        return {'topic': self.topic, 'offset_ns': int(self.offset_ns), 'skew_ppm': float(self.skew_ppm),
                'anchor_ns': int(self.anchor_ns), 'accepted': bool(self.accepted), 'cost': _finite(self.cost),
                'confidence': _finite(self.confidence), 'window_ns': [int(self.window_ns[0]), int(self.window_ns[1])],
                'uncertainty_ns': _finite(self.uncertainty_ns),
                'skew_uncertainty_ppm': _finite(self.skew_uncertainty_ppm),
                'reason': self.reason, 'windows_agreeing': int(self.windows_agreeing),
                'windows_total': int(self.windows_total), 'spread_ns': _finite(self.spread_ns),
                'prior': None if self.prior is None else self.prior.value, 'prior_reason': self.prior_reason,
                **({'trigger_edges': self.edges, 'density_offset_ns': self.density_offset_ns} if self.edges else {}),
                **({'trigger_tied_to': self.tied_to} if self.tied_to else {})}

    @classmethod
    def from_json(cls, doc: Mapping[str, Any]) -> CameraFit:
        """A camera entry back from JSON. ``topic``, ``offset_ns``, ``skew_ppm`` and ``anchor_ns`` are
        required (a hand-written correction needs no more); ``accepted`` defaults to true, ``cost``
        and ``confidence`` to NaN, ``window_ns`` to the anchor. Raises KeyError, TypeError or
        ValueError (``RigFit.from_json`` names the document)."""
        topic = doc['topic']
        if not isinstance(topic, str) or not topic:
            raise ValueError(f'topic must be a non-empty string, got {topic!r}')
        for name in ('offset_ns', 'anchor_ns'):
            if isinstance(doc[name], bool) or not isinstance(doc[name], int):
                raise ValueError(f'{name} of {topic} must be an integer, got {doc[name]!r}')
        skew = float(doc['skew_ppm'])
        if not math.isfinite(skew):
            raise ValueError(f'skew_ppm of {topic} is not finite')
        anchor = int(doc['anchor_ns'])
        start, end = doc.get('window_ns', (anchor, anchor))
        return cls(topic=topic, offset_ns=int(doc['offset_ns']), skew_ppm=skew, anchor_ns=anchor,
                   accepted=bool(doc.get('accepted', True)), cost=_number(doc.get('cost')),
                   confidence=_number(doc.get('confidence')), window_ns=(int(start), int(end)),
                   uncertainty_ns=_optional(doc.get('uncertainty_ns')),
                   skew_uncertainty_ppm=_optional(doc.get('skew_uncertainty_ppm')), reason=str(doc.get('reason', '')),
                   kind=Reason.of(str(doc.get('reason', ''))),
                   windows_agreeing=int(doc.get('windows_agreeing', 0)), windows_total=int(doc.get('windows_total', 0)),
                   spread_ns=_optional(doc.get('spread_ns')),
                   prior=None if doc.get('prior') is None else Prior.of(doc['prior']),
                   prior_reason=str(doc.get('prior_reason', '')))


@dataclass(frozen=True, kw_only=True)
class RigFit:
    """Every camera's estimate against one reference: the contract's whole object."""

    reference: str
    cameras: tuple[CameraFit, ...]
    """The reference first (offset 0), then the others in input order."""
    pair_residual_ns: dict[tuple[str, str], int] = field(default_factory=dict)
    """For accepted cameras i, j (neither the reference): what j's corrected times still need to agree
    with i's corrected times (0 when the two estimates are consistent)."""
    host: HostFit | None = None
    """With reference ``host``: the map of the cameras' common timeline onto host time."""
    latencies: dict[str, Any] | None = None
    """The known envelope latencies taken out, and where from (``latencies_ns``, ``latencies_file``);
    None: none were."""

    @classmethod
    def of(cls, cameras: Mapping[str, CameraFit], *, reference: str, start_ns: int, window_ns: int,
           order: Iterable[str], pair_residual_ns: Mapping[tuple[str, str], int] | None = None) -> RigFit:
        """The cameras' decisions (by topic) in the contract's form: the reference's entry first,
        the others in ``order``."""
        ref = CameraFit.reference_entry(reference, start_ns=start_ns, window_ns=window_ns)
        return cls(reference=reference, cameras=(ref, *(cameras[t] for t in order if t != reference)),
                   pair_residual_ns=dict(pair_residual_ns or {}))

    def camera(self, topic: str) -> CameraFit:
        """The entry of ``topic``; StreamError when the rig has none."""
        for cam in self.cameras:
            if cam.topic == topic:
                return cam
        raise StreamError(f'no estimate for {topic} (cameras: {", ".join(c.topic for c in self.cameras)})')

    @property
    def corrections(self) -> dict[str, ClockCorrection]:
        """Each camera's correction onto the reference timeline (the reference's is the identity)."""
        return {c.topic: c.correction for c in self.cameras}

    def as_json(self) -> dict[str, Any]:
        """The contract's object (what ``evsync estimate --json`` prints)."""
        doc: dict[str, Any] = {'reference': self.reference, 'cameras': [c.as_json() for c in self.cameras]}
        if self.host is not None:
            doc['host'] = self.host.as_json()
        if self.latencies is not None:
            doc.update(self.latencies)
        return doc

    def on_host(self, fit: HostFit) -> RigFit:
        """This rig (every camera on one camera's timeline) put on host time by ``fit``: reference
        ``host``, each camera's correction followed by the host map, its uncertainty the two
        combined; a camera not accepted stays not accepted. The pair residuals stay: they are between
        cameras, whatever timeline the rig is on."""
        if self.reference == HOST:
            raise StreamError('the rig is on host time already')
        cams = []
        for c in self.cameras:
            both = c.correction.then(fit.correction)
            u = math.hypot(c.uncertainty_ns or 0.0, fit.uncertainty_ns) if c.uncertainty_ns is not None else None
            cams.append(replace(c, offset_ns=both.offset_ns, skew_ppm=both.skew_ppm, anchor_ns=both.anchor_ns,
                                uncertainty_ns=u))
        return replace(self, reference=HOST, cameras=tuple(cams), host=fit)

    @classmethod
    def from_json(cls, doc: Any, *, source: str = 'JSON') -> RigFit:
        """The contract's object back from parsed JSON; ParameterError naming ``source`` when ``doc``
        is not one (see ``CameraFit.from_json`` for the fields a camera needs)."""
        if isinstance(doc, dict) and 'bags' in doc and 'reference' not in doc:
            raise ParameterError(f'{source}: the JSON of several bags ({{"bags": [...]}}); each bag\'s estimate is '
                                 'its entry\'s "estimate": give one bag\'s, or estimate that bag alone with --json')
        try:
            reference = doc['reference']
            cameras = tuple(CameraFit.from_json(c) for c in doc['cameras'])
        except (KeyError, TypeError, ValueError) as exc:
            raise ParameterError(f'{source}: not an evsync estimate ({{"reference", "cameras": [{{"topic", '
                                 f'"offset_ns", '
                                 f'"skew_ppm", "anchor_ns", ...}}]}}): {exc!r}') from exc
        topics = [c.topic for c in cameras]
        if reference not in topics and reference != HOST:
            raise ParameterError(f'{source}: the reference {reference} is not among its cameras')
        if len(set(topics)) != len(topics):
            raise ParameterError(f'{source}: a topic appears twice among its cameras ({", ".join(topics)})')
        return cls(reference=reference, cameras=cameras)

    def with_latencies(self, latencies_ns: Mapping[str, int]) -> RigFit:
        """The estimate with each camera's known envelope latency taken out.

        A density method aligns event-rate envelopes; a camera whose envelope lags the world by L
        (a slower photoreceptor, a higher threshold) has L - L_reference added to its true offset's
        estimate, and nothing in the envelopes tells that lag from a clock offset. ``latencies_ns``
        maps topics to L (ns; a topic not listed has 0), known from the camera models or measured
        once on a rig with a trigger cable. Offsets become offset + L_camera - L_reference.
        StreamError for a latency given for a topic not in the rig.
        """
        delta = latency_deltas(latencies_ns, topics=[c.topic for c in self.cameras], reference=self.reference)
        cams = [replace(c, offset_ns=c.offset_ns + delta[c.topic]) if c.topic != self.reference else c
                for c in self.cameras]
        return replace(self, cameras=tuple(cams))


def _finite(value: float | None) -> float | None:
    """A float for JSON, None (null) for what JSON cannot hold (NaN, inf) or what is not known."""
    return float(value) if value is not None and math.isfinite(value) else None


def _number(value: Any) -> float:
    """A float from JSON: null reads as NaN (not known)."""
    return math.nan if value is None else float(value)


def _optional(value: Any) -> float | None:
    return None if value is None else float(value)


def load_rig(path: str | Path) -> RigFit:
    """The contract's object from a JSON file (``evsync estimate --json > FILE``); ParameterError
    naming the file when it cannot be read or is not one."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except OSError as exc:
        raise ParameterError(f'{path}: cannot read offsets: {exc}') from exc
    except json.JSONDecodeError as exc:
        raise ParameterError(f'{path}: not JSON ({exc})') from exc
    return RigFit.from_json(doc, source=str(path))


def latency_deltas(latencies_ns: Mapping[str, int], *, topics: Iterable[str], reference: str) -> dict[str, int]:
    """Each topic's known envelope latency minus the reference's (ns; a topic not listed has 0): what
    its offset gets added. StreamError for a latency given for a topic not among ``topics``."""
    topics = list(topics)
    unknown = sorted(set(latencies_ns) - set(topics))
    if unknown:
        raise StreamError(f'latency given for {", ".join(unknown)}, not among the estimated topics {topics}')
    ref = int(latencies_ns.get(reference, 0))
    return {t: int(latencies_ns.get(t, 0)) - ref for t in topics}
