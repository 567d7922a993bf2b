"""Parameter files in ROS 2 form: ``<node>: {ros__parameters: {...}}``, read without rclpy."""

from __future__ import annotations

import array
import contextlib
import difflib
import math
import sys
from collections.abc import Callable, Collection, Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ruamel.yaml import YAML
from ruamel.yaml.error import YAMLError

from evsync_ros.core.engine import EngineParams
from evsync_ros.core.host import HOST
from evsync_ros.core.latencies import Latencies, combined
from evsync_ros.core.paper import PaperParams
from evsync_ros.core.refined import RefinedParams
from evsync_ros.core.results import METHODS, PriorChoice
from evsync_ros.errors import ParameterError
from evsync_ros.ros.modes import BeforeLock, Estimator, Executor, Kind, Processes, Qos, Reliability, Republish
from msg_adapters.definitions import EVENT_TYPES
from msg_adapters.registry import is_event_type

#: Estimator parameters as named in the YAML, and their PaperParams field and unit.
PAPER_KEYS = {
    'tau_ms': ('tau_ns', 1e6),
    'window_s': ('window_ns', 1e9),
    'epsilon': ('epsilon', None),
    'percentile': ('percentile', None),
    'min_overlap': ('min_overlap', None),
}


def load_ros_parameters(path: str | Path, *, node: str = 'evsync', rcl: bool = False) -> dict[str, Any]:
    """The ``ros__parameters`` of ``node`` (or of the wildcard ``/**``) in a parameter file. ``rcl``:
    as rcl resolves them for a node of that name where rclpy is present (wildcards merged under the
    node's own keys, ``/**/evsync`` and namespaced keys matched), as ``evsync_node`` would read the
    file; else the first of the sections ``node``, ``/node``, ``/**``."""
    path = Path(path)
    if rcl and path.is_file():
        values = _rcl_parameters(path, node)
        if values is not None:
            if not values:
                raise ParameterError(f'{path}: no parameters for node {node} (no {node}: ros__parameters section, '
                                     'nor a wildcard that matches it)')
            return values
    try:
        doc = YAML(typ='safe').load(path.read_text())
    except (OSError, YAMLError) as exc:
        raise ParameterError(f'{path}: cannot read parameter file: {exc}') from exc
    for key in (node, f'/{node}', '/**'):
        section = (doc or {}).get(key) if isinstance(doc, dict) else None
        if isinstance(section, dict) and isinstance(section.get('ros__parameters'), dict):
            return dict(section['ros__parameters'])
    raise ParameterError(f'{path}: no {node}: ros__parameters section')


ROS_OWN = ('use_sim_time', 'start_type_description_service')
"""Parameters every rclpy node declares itself."""


def _rcl_parameters(path: Path, node: str) -> dict[str, Any] | None:
    """What rcl gives a node named ``node`` started with ``--params-file path`` (None: no rclpy)."""
    try:
        import rclpy
        from rclpy.context import Context
    except ImportError:
        return None
    context = Context()
    try:
        rclpy.init(context=context, args=['--ros-args', '--params-file', str(path)])
    except Exception as exc:  # rcl's parse errors come as several types
        raise ParameterError(f'{path}: rcl cannot read it as a parameter file: {exc}') from exc
    try:
        probe = rclpy.create_node(node, context=context, automatically_declare_parameters_from_overrides=True,
                                  start_parameter_services=False, enable_rosout=False)
        try:
            return {name: probe.get_parameter(name).value for name in probe._parameters
                    if name not in ROS_OWN}
        finally:
            probe.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def paper_params_from(values: dict[str, Any], *, source: str) -> PaperParams:
    """PaperParams from YAML-named values; unknown estimator keys are ignored by design."""
    kwargs: dict[str, Any] = {}
    for key, (name, scale) in PAPER_KEYS.items():
        if key not in values:
            continue
        value = values[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f'{source}: {key} must be a number, got {value!r}')
        kwargs[name] = round(value * scale) if scale else float(value)
    return PaperParams(**kwargs)


# --- the live node's parameters (declared by node.py; checked here, without rclpy) ---------------

@dataclass(frozen=True)
class Spec:
    """One node parameter: its kind, what it means, and its allowed values."""

    kind: Kind
    """Its type (an array's bounds hold for each item)."""
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    optional: bool = False
    """May be left out of the parameter files (an empty array, which ROS parameter files cannot write)."""


PRIORS_CHOSEN = tuple(c.value for c in PriorChoice)
"""The choices of ``prior``."""

NODE_PARAMETERS: dict[str, Spec] = {
    'topics': Spec(Kind.STRING_ARRAY, 'event topics to synchronise (two to eight)'),
    'types': Spec(Kind.STRING_ARRAY, 'message type of each topic, or one type for all'),
    'reference': Spec(Kind.STRING, "topic whose timeline the others join ('' = the first topic; host = the host "
                      'clock)'),
    'method': Spec(Kind.STRING, 'estimator: refined or paper', choices=METHODS),
    'tau_ms': Spec(Kind.DOUBLE, 'density bin width tau (ms)', 0.01, 100.0),
    'window_s': Spec(Kind.DOUBLE, "estimation window T (s): the paper's; the refined method's longest", 0.5, 120.0),
    'epsilon': Spec(Kind.DOUBLE, 'paper: accept a window when min D < epsilon', 1e-12, 1.0),
    'percentile': Spec(Kind.DOUBLE, "paper: the search range's percentile", 1.0, 99.0),
    'min_overlap': Spec(Kind.DOUBLE, 'least fraction of the window a shift must overlap', 0.0, 0.99),
    'min_confidence': Spec(Kind.DOUBLE, 'refined: the least share of the windows with a clear peak that must agree',
                           0.0, 1.0),
    'envelope_latency_us': Spec(Kind.DOUBLE_ARRAY, "each camera's known envelope latency (us; one per topic, or one "
                                'for all: none), taken out of its offset', -1e6, 1e6),
    'trigger_channels': Spec(Kind.STRING_ARRAY, "TOPIC=ID per camera whose trigger input has the rig's shared pulse "
                             '(evt3 EXT_TRIGGER edges): its line taken from the edges once its density decision '
                             'picks the pulse (processes: one)', optional=True),
    'latencies_file': Spec(Kind.STRING, 'envelope latencies measured against trigger edges (evsync verify '
                           "--save-latencies): its cameras' taken out of their offsets ('' = none)"),
    'search_range_s': Spec(Kind.DOUBLE, 'refined: search half-range around the arrival-time offset (s)', 0.001, 30.0),
    'prior': Spec(Kind.STRING, "what places each camera's windows: auto (its arrival times where they behave as one "
                  "clock's, else its events alone), arrival or events", choices=PRIORS_CHOSEN),
    'estimate_period_s': Spec(Kind.DOUBLE, 'period of the estimation timer (s)', 0.05, 60.0),
    'drift_span_s': Spec(Kind.DOUBLE, 'span of accepted windows the offset line is fitted over (s)', 1.0, 3600.0),
    'silence_s': Spec(Kind.DOUBLE, 'a stream silent this long is reported lost (s)', 0.1, 600.0),
    'jump_threshold_s': Spec(Kind.DOUBLE, 'a clock moving this much against arrival times jumped (s)', 0.01, 1e6),
    'step_threshold_ms': Spec(Kind.DOUBLE, 'a window this far off the line, twice, is a clock step (ms)', 0.01, 1e5),
    'output_suffix': Spec(Kind.STRING, 'restamped <topic> is published on <topic><suffix>'),
    'output_namespace': Spec(Kind.STRING, 'when set, restamped <topic> is published on <namespace><topic>'),
    'offsets_topic': Spec(Kind.STRING, 'topic of the sensor_msgs/TimeReference offsets'),
    'status_topic': Spec(Kind.STRING, "numeric per-camera status for plotting tools: a std_msgs/Float64 per quantity "
                         "on <status_topic><topic>/<quantity> (offset_ms, skew_ppm, offset_std_ms ...; '' = none)"),
    'diagnostics_period_s': Spec(Kind.DOUBLE, 'period of /diagnostics and of the offsets (s)', 0.05, 60.0),
    'log_summary_s': Spec(Kind.DOUBLE, "period of the log's one-line summary of every camera (s; 0: none)", 0.0,
                          86400.0),
    'qos': Spec(Kind.STRING, 'QoS of the event inputs: sensor_data (best effort) or reliable (outputs reliable '
                'too, whatever output_reliability says)', choices=Qos.choices()),
    'qos_depth': Spec(Kind.INTEGER, 'history depth of inputs and outputs', 1, 100000),
    'output_reliability': Spec(Kind.STRING, 'reliability of the restamped event outputs: best_effort (as the drivers '
                               'publish) or reliable (what subscribers ask by default, message_filters too; it '
                               'serves best-effort ones as well, and a slow subscriber slows the node)',
                               choices=Reliability.choices()),
    'before_lock': Spec(Kind.STRING, "a camera's messages before its lock: coarse (the arrival-time offset), "
                        'forward (unshifted) or hold (until the lock)',
                        choices=BeforeLock.choices()),
    'hold_limit_s': Spec(Kind.DOUBLE, 'hold: messages held longer go out unshifted (s)', 0.1, 3600.0),
    'processes': Spec(Kind.STRING, "one (everything in the node's process) or per_camera (a restamping process per "
                      'camera feeding the estimator counts)', choices=Processes.choices()),
    'offsets_file': Spec(Kind.STRING, "saved offsets (evsync estimate --json's contract): each accepted camera in it "
                         "is corrected from its first message (state seeded) until its own estimate agrees; "
                         "~/save_offsets writes it ('' = none)"),
    'republish': Spec(Kind.STRING, 'all (every stream restamped on its output, companions too) or none (offsets and '
                      'diagnostics only: no event bandwidth doubled over DDS)', choices=Republish.choices()),
    'executor': Spec(Kind.STRING, "events (rclpy's EventsExecutor, in C++: a third of the per-message cost) or "
                     'single_threaded (rclpy.spin)', choices=Executor.choices()),
    'estimator': Spec(Kind.STRING, 'process (windows fitted in a process of their own: the message path keeps the '
                      "interpreter's lock) or thread (in the node's process)", choices=Estimator.choices()),
    'estimator_nice': Spec(Kind.INTEGER, 'estimator process: niceness added to its own (0: as the node; 19: it '
                           'takes only what the message path leaves)', 0, 19),
    'host_latency_us': Spec(Kind.DOUBLE, 'reference host: the least latency from an event to the host, if known (us)',
                            0.0, 1e6),
    'companions': Spec(Kind.STRING_ARRAY, "topics on an event camera's clock (its IMU, frames, camera_info), each "
                       'TOPIC=EVENT_TOPIC: restamped with that camera (header.stamp) on <TOPIC><suffix>',
                       optional=True),
    'companion_types': Spec(Kind.STRING_ARRAY, 'message type of each companion, or one type for all', optional=True),
}


RUNTIME = ('min_confidence', 'diagnostics_period_s', 'before_lock')
"""Parameters ``ros2 param set`` may change while the node runs; every other one is read only."""

DEPRECATED = {'hop_s': "not used since the paper's windows follow one another on every path"}
"""Parameters the node no longer has, accepted (a parameter file that sets one still loads) and
warned about once, with why."""
QOS_OVERRIDES = 'qos_overrides.'
"""The prefix of rclpy's QoS override parameters (``ros.qos``)."""


def unknown_parameters(names: Iterable[str], *, entities: Collection[str] | None = None
                       ) -> tuple[list[str], list[str]]:
    """Of the parameter names a node was given: (those it does not know, each with the nearest it
    does if one is close: ``windw_s (did you mean window_s?)``, those deprecated with why). rclpy's
    own are known, and its QoS overrides of ``entities`` (``<topic>.<publisher|subscription>``; None:
    of any topic)."""
    known = [*NODE_PARAMETERS, *ROS_OWN]
    unknown, deprecated = [], []
    for name in sorted(names):
        if name in known:
            continue
        if name.startswith(QOS_OVERRIDES):
            entity = name[len(QOS_OVERRIDES):].rpartition('.')[0]
            if entities is not None and entity not in entities:
                unknown.append(f'{name} (no publisher or subscription of this node on that topic)')
            continue
        if name in DEPRECATED:
            deprecated.append(f'{name} ({DEPRECATED[name]})')
            continue
        near = difflib.get_close_matches(name, NODE_PARAMETERS, n=1)
        unknown.append(f'{name} (did you mean {near[0]}?)' if near else name)
    return unknown, deprecated


def checked_value(name: str, value: Any, *, source: str) -> Any:
    """One parameter's value checked against its Spec (ParameterError naming it)."""
    return _checked(name, NODE_PARAMETERS[name], value, source)


def shipped_parameters() -> Path:
    """The node's defaults: config/evsync.yaml as installed (share/evsync_ros) or in the source tree."""
    candidates = [Path(__file__).resolve().parents[2] / 'config' / 'evsync.yaml',
                  Path(sys.prefix) / 'share' / 'evsync_ros' / 'config' / 'evsync.yaml']
    with contextlib.suppress(Exception):  # no ament index, or the package not in it: try the others
        from ament_index_python.packages import get_package_share_directory
        candidates.insert(0, Path(get_package_share_directory('evsync_ros')) / 'config' / 'evsync.yaml')
    for path in candidates:
        if path.is_file():
            return path
    raise ParameterError(f'evsync.yaml (the node defaults) not found in {", ".join(map(str, candidates))}')


def node_defaults(path: str | Path | None = None) -> dict[str, Any]:
    """Every node parameter's default, from the shipped YAML (all must be there, and no others)."""
    path = Path(path) if path else shipped_parameters()
    values = load_ros_parameters(path)
    missing = sorted(n for n, spec in NODE_PARAMETERS.items() if n not in values and not spec.optional)
    unknown = sorted(set(values) - set(NODE_PARAMETERS))
    if missing or unknown:
        raise ParameterError(f'{path}: parameters missing {missing}, unknown {unknown}')
    return {**{n: None for n, spec in NODE_PARAMETERS.items() if spec.optional}, **values}


@dataclass(frozen=True)
class Companion:
    """A topic on an event camera's clock, republished with that camera's correction."""

    topic: str
    camera: str
    """The event topic whose correction it gets."""
    msgtype: str
    output: str


@dataclass(frozen=True)
class NodeConfig:
    """The node's checked configuration."""

    topics: tuple[str, ...]
    types: tuple[str, ...]
    reference: str
    online: EngineParams
    estimate_period_ns: int
    outputs: tuple[str, ...]
    offsets_topic: str
    diagnostics_period_ns: int
    qos: Qos
    qos_depth: int
    before_lock: BeforeLock
    hold_limit_ns: int
    latencies_ns: dict[str, int]
    """Known envelope latencies (``envelope_latency_us``; empty when one value is given for all)."""
    companions: tuple[Companion, ...] = ()
    host: bool = False
    """reference ``host``: every camera onto the host clock (``reference`` is then the first topic, the
    timeline the cameras join before the host map)."""
    host_floor_ns: int = 0
    processes: Processes = Processes.ONE
    """``per_camera``: each camera's messages restamped in a process of its own (``ros.camera``)."""
    executor: Executor = Executor.EVENTS
    """What spins the node and its camera processes (``ros.spin``)."""
    estimator: Estimator = Estimator.PROCESS
    """Where the windows are fitted and their agreement found (``core.runner``, ``runtime.runner``)."""
    estimator_nice: int = 0
    """The estimator process's niceness, added to the node's."""
    republish: Republish = Republish.ALL
    """``none``: offsets and diagnostics only; no stream or companion is republished."""
    offsets_file: str = ''
    """Saved offsets that seed the cameras at start, and where ``~/save_offsets`` writes ('': none)."""
    status_topic: str = '/evsync/status'
    """Where the numeric per-camera status goes (``ros.status``; '': not published)."""
    output_reliability: Reliability = Reliability.BEST_EFFORT
    """The restamped event outputs' reliability (``ros.qos.output_qos``)."""
    log_summary_ns: int = 30_000_000_000
    """How often the log sums every camera up in a line (0: never)."""
    trigger_channels: dict[str, int] = field(default_factory=dict)
    """Per camera, the trigger input its shared pulse comes in on (``trigger_channels``)."""


def node_config(values: dict[str, Any], *, source: str = 'parameters') -> NodeConfig:
    """Check every value against its Spec and derive the estimator's parameters; ParameterError
    names the parameter."""
    v: dict[str, Any] = {}
    for name, spec in NODE_PARAMETERS.items():
        if spec.optional and values.get(name) is None:
            v[name] = None
            continue
        if name not in values:
            raise ParameterError(f'{source}: parameter {name} is not set')
        v[name] = _checked(name, spec, values[name], source)
    topics = tuple(v['topics'])
    if not 2 <= len(topics) <= 8:
        raise ParameterError(f'{source}: topics must name two to eight topics, got {len(topics)}')
    if len(set(topics)) != len(topics) or not all(t.startswith('/') for t in topics):
        raise ParameterError(f'{source}: topics must be distinct absolute names, got {list(topics)}')
    types = tuple(v['types'])
    if len(types) == 1:
        types *= len(topics)
    if len(types) != len(topics):
        raise ParameterError(f'{source}: types must give one type, or one per topic ({len(topics)}), got {len(types)}')
    for t in types:
        if not is_event_type(t):
            raise ParameterError(f"{source}: types: '{t}' is not an event message type ({', '.join(EVENT_TYPES)})")
    latency = v['envelope_latency_us']
    if len(latency) not in (1, len(topics)):
        raise ParameterError(f'{source}: envelope_latency_us must give one latency per topic ({len(topics)}), or one '
                             f'for all, got {len(latency)}')
    latencies_ns = {t: round(x * 1000) for t, x in zip(topics, latency)} if len(latency) > 1 else {}
    if v['latencies_file']:
        latencies_ns = _from_file(v['latencies_file'], latencies_ns, topics=topics, source=source)
    host = v['reference'] == HOST
    reference = (v['reference'] if not host else '') or topics[0]
    if reference not in topics:
        raise ParameterError(f'{source}: reference {reference!r} is not among topics {list(topics)}')
    if v['output_namespace']:
        outputs = tuple(v['output_namespace'].rstrip('/') + t for t in topics)
    elif v['output_suffix']:
        outputs = tuple(t + v['output_suffix'] for t in topics)
    else:
        raise ParameterError(f'{source}: output_suffix and output_namespace are both empty: '
                             'outputs would be the inputs')
    companions = _companions(v['companions'] or [], v['companion_types'] or [], topics=topics,
                             outputs=dict(zip(topics, outputs)), suffix=v['output_suffix'],
                             namespace=v['output_namespace'], source=source)
    ms, s = 1_000_000, 1_000_000_000
    tau = round(v['tau_ms'] * ms)
    try:
        paper = PaperParams(tau_ns=tau, window_ns=round(v['window_s'] * s), epsilon=v['epsilon'],
                            percentile=v['percentile'], min_overlap=v['min_overlap'])
        refined = RefinedParams(tau_ns=tau, window_ns=paper.window_ns,
                                min_window_ns=min(RefinedParams().min_window_ns, paper.window_ns),
                                max_shift_ns=round(v['search_range_s'] * s), min_overlap=max(v['min_overlap'], 0.01),
                                min_confidence=v['min_confidence'])
        online = EngineParams(method=v['method'], refined=refined, paper=paper, prior=v['prior'],
                              drift_span_ns=round(v['drift_span_s'] * s), silence_ns=round(v['silence_s'] * s),
                              jump_ns=round(v['jump_threshold_s'] * s), step_ns=round(v['step_threshold_ms'] * ms))
    except ParameterError as exc:
        raise ParameterError(f'{source}: {exc} (from tau_ms, window_s ...)') from exc
    if v['status_topic'] and not v['status_topic'].startswith('/'):
        raise ParameterError(f"{source}: status_topic must be an absolute name or '', got {v['status_topic']!r}")
    grid = online.grid_ns
    if online.window_ns % grid:
        raise ParameterError(f'{source}: window_s must be a whole number of {grid / ms:g} ms bins')
    return NodeConfig(topics=topics, types=types, reference=reference, online=online,
                      estimate_period_ns=round(v['estimate_period_s'] * s), outputs=outputs,
                      offsets_topic=v['offsets_topic'], diagnostics_period_ns=round(v['diagnostics_period_s'] * s),
                      qos=Qos(v['qos']), qos_depth=v['qos_depth'], before_lock=BeforeLock(v['before_lock']),
                      hold_limit_ns=round(v['hold_limit_s'] * s), latencies_ns=latencies_ns, companions=companions,
                      host=host, host_floor_ns=round(v['host_latency_us'] * 1000),
                      processes=Processes(v['processes']), executor=Executor(v['executor']),
                      estimator=Estimator(v['estimator']), estimator_nice=v['estimator_nice'],
                      republish=Republish(v['republish']), offsets_file=v['offsets_file'],
                      status_topic=v['status_topic'], output_reliability=Reliability(v['output_reliability']),
                      log_summary_ns=round(v['log_summary_s'] * s),
                      trigger_channels=_trigger_channels(v['trigger_channels'] or [], topics=topics,
                                                         processes=v['processes'], source=source))


def _trigger_channels(pairs: list[str], *, topics: tuple[str, ...], processes: str, source: str) -> dict[str, int]:
    """``trigger_channels`` as {topic: channel}; ParameterError naming the entry."""
    out = {}
    for item in pairs:
        topic, sep, value = item.partition('=')
        if not sep or topic not in topics or not value.isdigit():
            raise ParameterError(f"{source}: trigger_channels wants TOPIC=ID with TOPIC one of topics, got '{item}'")
        out[topic] = int(value)
    if out and processes != Processes.ONE.value:
        raise ParameterError(f'{source}: trigger_channels needs processes: one (edges are read in the node)')
    return out


def _from_file(path: str, given: dict[str, int], *, topics: tuple[str, ...], source: str) -> dict[str, int]:
    """``latencies_file``'s latencies of ``topics`` with those ``envelope_latency_us`` gives (not 0);
    ParameterError for a camera in both."""
    try:
        file = Latencies.load(path)
    except ParameterError as exc:
        raise ParameterError(f'{source}: latencies_file: {exc}') from exc
    file = replace(file, latencies_ns={t: ns for t, ns in file.latencies_ns.items() if t in topics})
    both = combined(file, {t: ns for t, ns in given.items() if ns}, source=f'latencies_file {path}',
                    given_by='envelope_latency_us')
    return {t: both.get(t, 0) for t in topics}


def _companions(pairs: list[str], types: list[str], *, topics: tuple[str, ...], outputs: dict[str, str], suffix: str,
                namespace: str, source: str) -> tuple[Companion, ...]:
    """The companions of ``companions`` and ``companion_types`` (ParameterError naming the entry)."""
    if not pairs:
        if types:
            raise ParameterError(f'{source}: companion_types given without companions')
        return ()
    if len(types) == 1:
        types = types * len(pairs)
    if len(types) != len(pairs):
        raise ParameterError(f'{source}: companion_types must give one type for all companions, or one per '
                             f'companion ({len(pairs)}), got {len(types)}')
    out: list[Companion] = []
    for pair, msgtype in zip(pairs, types):
        topic, sep, camera = pair.partition('=')
        if not sep or not topic.startswith('/') or not camera.startswith('/'):
            raise ParameterError(f'{source}: companions: {pair!r} is not TOPIC=EVENT_TOPIC (absolute names)')
        if camera not in topics:
            raise ParameterError(f'{source}: companions: {pair!r} names {camera}, not one of topics {list(topics)}')
        if topic in topics or topic in outputs.values() or topic in (c.topic for c in out):
            raise ParameterError(f'{source}: companions: {topic} is already an event topic, an output or a companion')
        if is_event_type(msgtype):
            raise ParameterError(f'{source}: companions: {topic} has an event type ({msgtype}); make it a topic')
        output = namespace.rstrip('/') + topic if namespace else topic + suffix
        out.append(Companion(topic=topic, camera=camera, msgtype=msgtype, output=output))
    return tuple(out)


def expected(spec: Spec) -> str:
    """What a parameter must be, as its errors say it: 'double in [0.5, 120]', 'string (one of ...)'."""
    if spec.choices:
        return f'{spec.kind.value.replace("_", " ")} (one of {", ".join(spec.choices)})'
    allowed = f' in [{spec.low:g}, {spec.high:g}]' if spec.low is not None else ''
    return f'{spec.kind.value.replace("_", " ")}{allowed}'


def _checked(name: str, spec: Spec, value: Any, source: str) -> Any:
    """``value`` as ``spec`` takes it (ParameterError naming the parameter and what it must be)."""
    try:
        return CHECKS[spec.kind](spec, value)
    except (TypeError, ValueError):
        raise ParameterError(f'{source}: {name} must be {expected(spec)}, got {value!r}') from None


def _string(spec: Spec, value: Any) -> str:
    if not isinstance(value, str) or (spec.choices and value not in spec.choices):
        raise ValueError(value)
    return value


def _strings(spec: Spec, value: Any) -> list[str]:
    if not isinstance(value, (list, tuple)) or not all(isinstance(x, str) and x for x in value):
        raise ValueError(value)
    return list(value)


def _number(spec: Spec, value: Any) -> float | int:
    if (isinstance(value, bool) or not isinstance(value, (int, float))
            or (spec.kind is Kind.INTEGER and not isinstance(value, int))):
        raise TypeError(value)
    if not math.isfinite(value) or (spec.low is not None and spec.high is not None
                                    and not spec.low <= value <= spec.high):
        raise ValueError(value)
    return int(value) if spec.kind is Kind.INTEGER else float(value)


def _numbers(spec: Spec, value: Any) -> list[float | int]:
    if not isinstance(value, (list, tuple, array.array)) or not len(value):
        raise ValueError(value)
    return [_number(replace(spec, kind=Kind.DOUBLE), x) for x in value]


CHECKS: dict[Kind, Callable[[Spec, Any], Any]] = {
    Kind.STRING: _string, Kind.STRING_ARRAY: _strings, Kind.DOUBLE: _number, Kind.INTEGER: _number,
    Kind.DOUBLE_ARRAY: _numbers,
}
"""Each kind's check of a value, which it returns as the node takes it (TypeError, ValueError otherwise)."""
