"""A per-pixel event-camera rig simulator: several cameras on one rig watching a shared world. numpy
only. Events come from each pixel's log intensity crossing its own contrast threshold; nothing here
is tuned to make an estimator look good. The model (world, camera, clocks): docs/simulator.md."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from evsync_ros.errors import ParameterError
from evsync_ros.sim.triggers import TriggerStamps, TriggerTrain, stamp_edges, train_edges

NS = 1_000_000_000


@dataclass(frozen=True)
class PixelCamera:
    """One camera of a rig: geometry, pixel model, clock and how it is written to a bag."""

    topic: str
    width: int = 64
    height: int = 48
    fov_deg: float = 60.0
    yaw_deg: float = 0.0
    """Where the camera looks on the rig (180: facing the other way)."""
    contrast: float = 0.20
    threshold_sigma: float = 0.03
    """Per-pixel threshold spread, as a fraction of ``contrast``."""
    lowpass_ns: int = 300_000
    refractory_ns: int = 100_000
    noise_hz: float = 0.1
    hot_pixels: int = 1
    hot_hz: float = 200.0
    start_ns: int = 0
    """True time at which the camera starts streaming."""
    clock_at_start_ns: int = 0
    skew_ppm: float = 0.0
    clock_step: tuple[int, int] | None = None
    """(at, by): from true time ``at`` on, the clock reads ``by`` ns more (a driver restarted, a
    timestamp reset; ``by`` > 0, as an evt3 stream's time only moves on). The truth is the clock
    before it."""
    encoding: str = 'evt3'
    """How the bag writer sends it: 'evt3' (EventPacket) or 'dvs' (dvs_msgs/EventArray)."""

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0 or not 0 < self.fov_deg < 180:
            raise ParameterError(f'{self.topic}: bad geometry {self.width}x{self.height}, fov {self.fov_deg}')
        if not self.contrast > 0 or self.threshold_sigma < 0 or self.lowpass_ns <= 0 or self.refractory_ns < 0:
            raise ParameterError(f'{self.topic}: contrast, spread, low-pass and refractory must be positive')
        if self.encoding not in ('evt3', 'dvs'):
            raise ParameterError(f"{self.topic}: encoding must be 'evt3' or 'dvs', got {self.encoding!r}")
        if self.clock_step is not None and not self.clock_step[1] > 0:
            raise ParameterError(f'{self.topic}: a clock step moves the clock on, got {self.clock_step[1]} ns')


@dataclass(frozen=True)
class Scene:
    """What the rig sees and how it moves."""

    duration_ns: int = 30 * NS
    motion: str = 'episodes'
    """'episodes' (bursts of turning between still spells), 'steady' (continuous turning) or 'still'."""
    speed_dps: float = 60.0
    """Typical turning speed, degrees per second."""
    light: float = 1.0
    """Scale of the scene's log-intensity contrast (low light: below 1)."""
    person: bool = False
    """A person-like object walks across the view (use with motion 'still')."""
    still_s: tuple[float, float] = (0.3, 1.5)
    """Range of the still spells between episodes (seconds)."""
    move_s: tuple[float, float] = (0.4, 2.0)
    """Range of the motion episodes (seconds)."""
    shake: float = 0.3
    """Hand-held or walking shake during motion: band-limited (up to ``shake_hz``) angular-velocity
    noise, as a fraction of the episode's speed."""
    shake_hz: float = 40.0


@dataclass(frozen=True)
class Rig:
    """Cameras on one rig in one scene; ``reference`` is the camera the others are estimated against."""

    cameras: tuple[PixelCamera, ...]
    scene: Scene = field(default_factory=Scene)
    seed: int = 0
    reference: str = ''
    dt_ns: int = 1_000_000
    triggers: TriggerTrain | None = None
    """A pulse train wired to every camera's trigger input (``evsync.sim.triggers``), None for none."""

    def __post_init__(self) -> None:
        if not self.cameras:
            raise ParameterError('a rig needs at least one camera')
        topics = [c.topic for c in self.cameras]
        if len(set(topics)) != len(topics):
            raise ParameterError(f'camera topics must be unique: {topics}')
        if not self.reference:
            object.__setattr__(self, 'reference', topics[0])
        if self.reference not in topics:
            raise ParameterError(f'reference {self.reference!r} is not a camera of the rig')

    def camera(self, topic: str) -> PixelCamera:
        return next(c for c in self.cameras if c.topic == topic)


# --- world ---------------------------------------------------------------------------------------

_PANO_RES = 0.25  # degrees per panorama sample
_PANO_W, _PANO_H = int(360 / _PANO_RES), int(120 / _PANO_RES)


def panorama(rng: np.random.Generator) -> np.ndarray:
    """Log intensity over 360 x 120 degrees: smooth random texture, std about 0.6."""
    noise = rng.standard_normal((_PANO_H, _PANO_W))
    fy = np.fft.fftfreq(_PANO_H)[:, None]
    fx = np.fft.rfftfreq(_PANO_W)[None, :]
    f = np.sqrt(fx ** 2 + fy ** 2) / _PANO_RES  # cycles per degree
    shaping = 1.0 / np.maximum(f, 0.01) ** 0.9 * np.exp(-(f / 0.35) ** 2)
    tex = np.fft.irfft2(np.fft.rfft2(noise) * shaping, s=noise.shape)
    tex -= tex.mean()
    return (tex * (0.6 / tex.std())).astype(np.float64)


def trajectory(scene: Scene, n_steps: int, dt_ns: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Rig yaw and pitch (degrees) at every step."""
    dt = dt_ns / NS
    if scene.motion == 'still':
        return np.zeros(n_steps), np.zeros(n_steps)
    if scene.motion == 'steady':
        return np.arange(1, n_steps + 1) * scene.speed_dps * dt, 5 * np.sin(np.arange(n_steps) * dt * 0.7)
    if scene.motion != 'episodes':
        raise ParameterError(f"scene motion must be 'episodes', 'steady' or 'still', got {scene.motion!r}")
    yaw_rate = np.zeros(n_steps)
    pitch_rate = np.zeros(n_steps)
    t = 0
    while t < n_steps:
        still = int(rng.uniform(*scene.still_s) * NS / dt_ns)
        move = int(rng.uniform(*scene.move_s) * NS / dt_ns)
        a, b = t + still, min(n_steps, t + still + move)
        if a < b:
            k = np.arange(b - a)
            env = np.sin(np.pi * k / max(1, b - a)) ** 2
            sign = rng.choice([-1.0, 1.0])
            wob = 1 + 0.5 * np.sin(2 * np.pi * k * dt * rng.uniform(1.0, 4.0) + rng.uniform(0, 6))
            yaw_rate[a:b] = sign * scene.speed_dps * rng.uniform(0.5, 1.5) * env * wob
            pitch_rate[a:b] = scene.speed_dps * 0.3 * rng.uniform(-1, 1) * env
        t = b
    if scene.shake:
        moving = np.abs(yaw_rate) / scene.speed_dps
        for rate in (yaw_rate, pitch_rate):
            rate += scene.shake * scene.speed_dps * moving * _band_limited(n_steps, dt, scene.shake_hz, rng)
    return np.cumsum(yaw_rate * dt), np.clip(np.cumsum(pitch_rate * dt), -20, 20)


def _band_limited(n: int, dt: float, f_max: float, rng: np.random.Generator) -> np.ndarray:
    """Unit-variance Gaussian noise with no power above ``f_max`` Hz."""
    spec = np.fft.rfft(rng.standard_normal(n))
    spec[np.fft.rfftfreq(n, dt) > f_max] = 0
    x = np.fft.irfft(spec, n)
    return x / max(x.std(), 1e-12)


def person_path(n_steps: int, dt_ns: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth of a person-like object crossing the view, walking to and fro with pauses."""
    dt = dt_ns / NS
    v = np.zeros(n_steps)
    t = 0
    direction = 1.0
    while t < n_steps:
        pause = int(rng.uniform(0.2, 1.0) * NS / dt_ns)
        walk = int(rng.uniform(1.0, 3.0) * NS / dt_ns)
        v[t + pause:t + pause + walk] = direction * rng.uniform(15, 30)
        direction = -direction
        t += pause + walk
    az = np.cumsum(v * dt)
    bob = 0.8 * np.abs(np.sin(np.arange(n_steps) * dt * 2 * np.pi * 1.8))
    return az, bob


# --- one camera ----------------------------------------------------------------------------------

def _sample(pano: np.ndarray, az: np.ndarray, el: np.ndarray) -> np.ndarray:
    """Bilinear lookup; azimuth wraps, elevation clamps."""
    x = (az / _PANO_RES) % _PANO_W
    y = np.clip(el / _PANO_RES + _PANO_H / 2, 0, _PANO_H - 1.001)
    x0 = np.floor(x).astype(np.intp)
    y0 = np.floor(y).astype(np.intp)
    fx = x - x0
    fy = y - y0
    x1 = (x0 + 1) % _PANO_W
    top = pano[y0, x0] * (1 - fx) + pano[y0, x1] * fx
    bot = pano[y0 + 1, x0] * (1 - fx) + pano[y0 + 1, x1] * fx
    return top * (1 - fy) + bot * fy


def photoreceptor_alpha(lowpass_ns: int, dt_ns: int) -> float:
    """The photoreceptor low-pass's step gain: level += alpha (input - level) every ``dt_ns``."""
    return 1 - math.exp(-dt_ns / lowpass_ns)


def render_camera(cam: PixelCamera, rig: Rig, pano: np.ndarray, yaw: np.ndarray, pitch: np.ndarray,
                  person: tuple[np.ndarray, np.ndarray] | None, rng: np.random.Generator
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Events of one camera in true time: (t_ns float64, x, y, polarity), unsorted."""
    dt = rig.dt_ns
    n_steps = yaw.size
    ifov = cam.fov_deg / cam.width
    u = (np.arange(cam.width) - cam.width / 2 + 0.5) * ifov
    v = (np.arange(cam.height) - cam.height / 2 + 0.5) * ifov
    uu, vv = np.meshgrid(u, v)
    uu, vv = uu.ravel(), vv.ravel()
    px = uu.size
    thresholds = cam.contrast * np.clip(1 + cam.threshold_sigma * rng.standard_normal(px), 0.3, None)
    alpha = photoreceptor_alpha(cam.lowpass_ns, dt)
    first = int(max(0, cam.start_ns) // dt)
    out_t: list[np.ndarray] = []
    out_i: list[np.ndarray] = []
    out_p: list[np.ndarray] = []
    level: np.ndarray | None = None
    ref = np.empty(0)
    last_fire = np.full(px, -np.inf)
    chunk = 256
    for c0 in range(first, n_steps, chunk):
        c1 = min(n_steps, c0 + chunk)
        az = yaw[c0:c1, None] + cam.yaw_deg + uu[None, :]
        el = pitch[c0:c1, None] + vv[None, :]
        lum = _sample(pano, az, el)
        if person is not None:
            paz, pbob = person
            dx = (az - paz[c0:c1, None] - 10.0) / 6.0
            dy = (el - pbob[c0:c1, None] + 2.0) / 18.0
            inside = dx * dx + dy * dy < 1
            stripes = 0.9 * np.sin(dy * 9.0) + 0.5 * np.sign(dx)
            lum = np.where(inside, stripes, lum)
        lum *= rig.scene.light
        for k in range(c1 - c0):
            step = c0 + k
            if level is None:
                level = lum[k].copy()
                ref = level.copy()
                continue
            prev = level
            level = prev + alpha * (lum[k] - prev)
            diff = level - ref
            fire = np.flatnonzero(np.abs(diff) >= thresholds)
            if fire.size == 0:
                continue
            d = diff[fire]
            th = thresholds[fire]
            n = np.floor(np.abs(d) / th).astype(np.int64)
            sgn = np.sign(d)
            rep = np.repeat(np.arange(fire.size), n)
            kth = np.arange(rep.size) - np.repeat(np.cumsum(n) - n, n) + 1  # 1..n per pixel
            pix = fire[rep]
            crossing = ref[pix] + sgn[rep] * kth * th[rep]
            span = level[pix] - prev[pix]
            frac = np.where(span != 0, (crossing - prev[pix]) / np.where(span != 0, span, 1), 1.0)
            t = (step - 1 + np.clip(frac, 0, 1)) * dt
            # refractory: successive events of a pixel at least refractory apart, after its last one
            t = np.maximum(t, last_fire[pix] + cam.refractory_ns * kth)
            last_fire[fire] = t[np.cumsum(n) - 1]
            ref[fire] += sgn * n * th
            out_t.append(t)
            out_i.append(pix)
            out_p.append((sgn[rep] > 0).astype(np.uint8))
    t = np.concatenate(out_t) if out_t else np.empty(0)
    idx = np.concatenate(out_i) if out_i else np.empty(0, np.intp)
    pol = np.concatenate(out_p) if out_p else np.empty(0, np.uint8)
    # background activity and hot pixels
    t0, t1 = max(0, cam.start_ns), n_steps * dt
    n_noise = rng.poisson(cam.noise_hz * px * (t1 - t0) / NS)
    hot = rng.choice(px, size=min(cam.hot_pixels, px), replace=False)
    n_hot = rng.poisson(cam.hot_hz * (t1 - t0) / NS, size=hot.size)
    t = np.concatenate([t, rng.uniform(t0, t1, n_noise), rng.uniform(t0, t1, int(n_hot.sum()))])
    idx = np.concatenate([idx, rng.integers(0, px, n_noise), np.repeat(hot, n_hot)])
    pol = np.concatenate([pol, rng.integers(0, 2, n_noise + int(n_hot.sum())).astype(np.uint8)])
    keep = t >= cam.start_ns
    t, idx, pol = t[keep], idx[keep], pol[keep]
    return t, (idx % cam.width).astype(np.uint16), (idx // cam.width).astype(np.uint16), pol


@dataclass(frozen=True)
class ImuSamples:
    """A camera's built-in IMU (a DAVIS has one), sampled on the camera's own clock."""

    t: np.ndarray
    """Sample times on the camera's clock, int64 ns."""
    true_t: np.ndarray
    """The same in true time (float64 ns)."""
    gyro: np.ndarray
    """(n, 3) angular velocity, rad/s, in the camera's frame (x right, y down, z forward), with
    white noise and a constant bias."""
    accel: np.ndarray
    """(n, 3) specific force, m/s^2: gravity seen by the pitched camera, with noise and bias."""


GYRO_NOISE = 0.003
"""Gyro white noise per sample (rad/s), and the bias bound below: of a MEMS IMU such as a DAVIS's."""
GYRO_BIAS = 0.01
ACCEL_NOISE = 0.02
ACCEL_BIAS = 0.05
GRAVITY = 9.81


@dataclass(frozen=True)
class CameraEvents:
    camera: PixelCamera
    t: np.ndarray
    """Event times on the camera's clock, int64 ns, sorted."""
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray
    true_t: np.ndarray
    """The same events in true time (float64 ns), for ground truth and lag measurements."""
    imu: ImuSamples | None = None
    """Its IMU's samples (``simulate(rig, imu_hz=...)``), None without one."""
    triggers: TriggerStamps | None = None
    """What its trigger input recorded of the rig's pulse train, None on a rig without one."""


def imu_samples(cam: PixelCamera, yaw_deg: np.ndarray, pitch_deg: np.ndarray, *, dt_ns: int, rate_hz: float,
                rng: np.random.Generator) -> ImuSamples:
    """What ``cam``'s IMU measures of the rig's turning (yaw about the vertical, pitch about the
    camera's horizontal axis), from its first streaming instant, at ``rate_hz``."""
    step = max(1, round(NS / rate_hz / dt_ns))
    idx = np.arange(0, yaw_deg.size, step)
    true_t = idx.astype(np.float64) * dt_ns
    keep = true_t >= cam.start_ns
    idx, true_t = idx[keep], true_t[keep]
    yaw_rate = np.deg2rad(np.gradient(yaw_deg, dt_ns / NS))[idx]
    pitch_rate = np.deg2rad(np.gradient(pitch_deg, dt_ns / NS))[idx]
    pitch = np.deg2rad(pitch_deg[idx])
    facing = math.cos(math.radians(cam.yaw_deg))  # a camera facing the other way sees pitch reversed
    n = idx.size
    gyro = np.stack([facing * pitch_rate, -yaw_rate, np.zeros(n)], axis=1)
    accel = np.stack([np.zeros(n), GRAVITY * np.cos(pitch), -facing * GRAVITY * np.sin(pitch)], axis=1)
    gyro += rng.uniform(-GYRO_BIAS, GYRO_BIAS, 3) + rng.normal(0, GYRO_NOISE, (n, 3))
    accel += rng.uniform(-ACCEL_BIAS, ACCEL_BIAS, 3) + rng.normal(0, ACCEL_NOISE, (n, 3))
    return ImuSamples(camera_clock(cam, true_t), true_t, gyro, accel)


def camera_clock(cam: PixelCamera, true_ns: np.ndarray) -> np.ndarray:
    """Clock reading of ``cam`` at true times (int64 ns)."""
    k = 1 + cam.skew_ppm * 1e-6
    true_ns = np.asarray(true_ns)
    elapsed = np.rint((true_ns.astype(np.float64) - cam.start_ns) * k).astype(np.int64)
    clock = elapsed + np.int64(cam.clock_at_start_ns)
    if cam.clock_step is not None:
        at, by = cam.clock_step
        clock = np.where(true_ns >= at, clock + np.int64(by), clock)
    return clock


def skew_against(ref: PixelCamera, cam: PixelCamera) -> float:
    """The skew (ppm) that takes ``cam``'s clock readings to ``ref``'s: (1 + s_ref) / (1 + s_cam) - 1."""
    return ((1 + ref.skew_ppm * 1e-6) / (1 + cam.skew_ppm * 1e-6) - 1) * 1e6


def simulate(rig: Rig, *, imu_hz: float = 0.0) -> dict[str, CameraEvents]:
    """Every camera's events, deterministic for the rig's seed; ``imu_hz`` > 0: and each camera's
    IMU samples at that rate (the events are the same with or without)."""
    if imu_hz < 0 or imu_hz > NS / rig.dt_ns:
        raise ParameterError(f'imu_hz must be within 0 to {NS / rig.dt_ns:g} (the simulation step), got {imu_hz}')
    root = np.random.default_rng(rig.seed)
    world_rng, motion_rng, person_rng = (np.random.default_rng(s) for s in root.integers(0, 2**63, 3))
    pano = panorama(world_rng)
    n_steps = int(rig.scene.duration_ns // rig.dt_ns)
    yaw, pitch = trajectory(rig.scene, n_steps, rig.dt_ns, motion_rng)
    person = person_path(n_steps, rig.dt_ns, person_rng) if rig.scene.person else None
    out = {}
    for i, cam in enumerate(rig.cameras):
        rng = np.random.default_rng([rig.seed, i, 7])
        t, x, y, p = render_camera(cam, rig, pano, yaw, pitch, person, rng)
        order = np.argsort(t, kind='stable')
        t, x, y, p = t[order], x[order], y[order], p[order]
        imu_rng = np.random.default_rng([rig.seed, i, 11])
        imu = imu_samples(cam, yaw, pitch, dt_ns=rig.dt_ns, rate_hz=imu_hz, rng=imu_rng) if imu_hz else None
        out[cam.topic] = CameraEvents(cam, camera_clock(cam, t), x, y, p, t, imu,
                                      _trigger_stamps(rig, i, t[0] if t.size else math.inf))
    return out


def _trigger_stamps(rig: Rig, i: int, first_event_ns: float) -> TriggerStamps | None:
    """Camera ``i``'s record of the rig's pulse train, from its first event on (an edge before it
    would have no anchor on an evt3 timeline), drawn from its own generator: the events are the same
    with or without triggers."""
    if rig.triggers is None:
        return None
    cam = rig.cameras[i]
    true_ns, value = train_edges(rig.triggers, rig.scene.duration_ns)
    return stamp_edges(rig.triggers, true_ns, value, from_ns=first_event_ns, clock=lambda t: camera_clock(cam, t),
                       rng=np.random.default_rng([rig.seed, i, 13]))


# --- presets -------------------------------------------------------------------------------------

def _clocks(rng: np.random.Generator, n: int, *, skew: bool) -> list[dict[str, Any]]:
    """Start times, clock readings and skews of n cameras: the first is the reference-like host clock."""
    out = []
    for i in range(n):
        start = int(rng.uniform(0.0, 1.5) * NS) if i else int(rng.uniform(0.0, 0.3) * NS)
        clock = 1_763_700_000 * NS + start if i == 0 else int(rng.choice([0, rng.uniform(0, 3e3) * NS,
                                                                        1_763_700_000 * NS + rng.uniform(-5, 5) * NS]))
        out.append({'start_ns': start, 'clock_at_start_ns': clock,
                    'skew_ppm': float(rng.uniform(-60, 60)) if (skew and i) else 0.0})
    return out


PRESETS = {
    'same-model': 'three identical 64x48 cameras side by side, episodic turning',
    'mixed-models': 'a 64x48 Prophesee-like, an 80x60 DAVIS-like with a higher threshold and slower photoreceptor, '
                    'a 48x36 DVXplorer-like: different resolution and threshold',
    'wide-baseline': 'three identical cameras looking 20 and 40 degrees apart',
    'opposite': 'two cameras facing opposite ways: different scenes, shared motion',
    'low-light': 'same-model cameras, scene contrast halved, slow photoreceptors, ten times the noise',
    'person': 'static rig, a person-like object walking to and fro',
    'bursty': 'short fast bursts of motion between long still spells',
    'drift': 'same-model cameras with clock skews of tens of ppm, 60 s',
    'slow-motion': 'three identical cameras on a rigid rig panning slowly in bursts (edges at about 20 px/s)',
    'fast-motion': 'three identical cameras on a rigid rig panning fast in bursts (edges at about 1500 px/s)',
    'two-makes-slow': 'two makes (threshold 0.22 against 0.30, 64x48 against 80x60, three times the noise) on a '
                      'rigid rig panning slowly in bursts (edges at about 20 px/s)',
    'two-makes-fast': 'the two makes of two-makes-slow panning fast in bursts (edges at about 1500 px/s)',
}

SLOW_PX_S = 20.0
"""Edge speed of the slow presets, in the reference camera's pixels per second."""
FAST_PX_S = 1500.0
"""Edge speed of the fast presets."""

MAKE_KEYS = {'contrast': ('contrast', 1.0), 'lowpass-us': ('lowpass_ns', 1_000),
             'refractory-us': ('refractory_ns', 1_000), 'noise-hz': ('noise_hz', 1.0)}
"""What ``make`` may set of a camera (``evsync simulate --make``): option key -> (field, scale)."""


def px_per_degree(cam: PixelCamera) -> float:
    """How many of ``cam``'s pixels a degree of turning sweeps an edge across."""
    return cam.width / cam.fov_deg


def parse_make(text: str) -> dict[str, Any]:
    """A make's pixel response from ``'contrast=0.30,lowpass-us=800,refractory-us=500'`` (any of
    ``MAKE_KEYS``), as ``PixelCamera`` fields."""
    out: dict[str, Any] = {}
    for item in filter(None, (part.strip() for part in text.split(','))):
        key, sep, value = item.partition('=')
        if not sep or key.strip() not in MAKE_KEYS:
            raise ParameterError(f"make: expected KEY=VALUE with KEY one of {', '.join(MAKE_KEYS)}, got {item!r}")
        field_name, scale = MAKE_KEYS[key.strip()]
        try:
            number = float(value)
        except ValueError:
            raise ParameterError(f'make: {key.strip()} must be a number, got {value!r}') from None
        out[field_name] = round(number * scale) if field_name.endswith('_ns') else number
    if not out:
        raise ParameterError(f'make: nothing to set in {text!r}')
    return out


def _preset_cameras(name: str) -> tuple[list[PixelCamera], Scene]:
    scene = Scene()
    base = [PixelCamera('/cam0/events'), PixelCamera('/cam1/events', encoding='dvs'),
            PixelCamera('/cam2/events')]
    if name == 'mixed-models':
        base = [PixelCamera('/prophesee/events', width=64, height=48, contrast=0.20, lowpass_ns=200_000),
                PixelCamera('/davis/events', width=80, height=60, fov_deg=62, contrast=0.30, threshold_sigma=0.06,
                            lowpass_ns=800_000, refractory_ns=300_000, noise_hz=0.3, encoding='dvs'),
                PixelCamera('/dvxplorer/events', width=48, height=36, fov_deg=58, contrast=0.25,
                            lowpass_ns=500_000, noise_hz=0.2)]
    elif name == 'wide-baseline':
        base = [replace(c, yaw_deg=20.0 * i) for i, c in enumerate(base)]
    elif name == 'opposite':
        base = [base[0], replace(base[1], yaw_deg=180.0)]
    elif name == 'low-light':
        scene = replace(scene, light=0.5)
        base = [replace(c, lowpass_ns=2_000_000, noise_hz=1.0) for c in base]
    elif name == 'person':
        scene = replace(scene, motion='still', person=True)
    elif name == 'bursty':
        scene = replace(scene, speed_dps=120.0, still_s=(1.5, 4.0), move_s=(0.15, 0.5))
    elif name in ('slow-motion', 'fast-motion', 'two-makes-slow', 'two-makes-fast'):
        # a rigid rig on a pan head: bursts of panning, little shake
        speed = SLOW_PX_S if 'slow' in name else FAST_PX_S
        if name.startswith('two-makes'):
            base = [PixelCamera('/make_a/events', contrast=0.22),
                    PixelCamera('/make_b/events', width=80, height=60, fov_deg=62, contrast=0.30,
                                threshold_sigma=0.06, noise_hz=0.3, encoding='dvs')]
        scene = replace(scene, speed_dps=speed / px_per_degree(base[0]), still_s=(0.5, 2.0), move_s=(1.0, 3.0),
                        shake=0.1)
    return base, scene


def preset(name: str, *, seed: int = 0, duration_s: float | None = None, speed_px_s: float | None = None,
           make: dict[str, Any] | None = None, triggers_hz: float = 0.0) -> Rig:
    """A rig of one of the kinds in ``PRESETS``; clocks (starts, readings, skews) drawn from the seed.

    ``speed_px_s``: the scene's typical edge speed instead of the preset's, in the reference
    camera's pixels per second (the rig turns at this over ``px_per_degree``). ``make``: ``PixelCamera``
    fields (``parse_make``) given to every camera but the reference: a camera of another make.
    ``triggers_hz`` > 0: a pulse train at that rate wired to every camera's trigger input
    (``TriggerTrain``'s other defaults); the events are the same as without."""
    if name not in PRESETS:
        raise ParameterError(f"unknown preset {name!r}; presets: {', '.join(PRESETS)}")
    rng = np.random.default_rng([seed, 99])
    duration = duration_s if duration_s is not None else (60.0 if name == 'drift' else 30.0)
    base, scene = _preset_cameras(name)
    scene = replace(scene, duration_ns=int(duration * NS))
    if speed_px_s is not None:
        if not speed_px_s > 0:
            raise ParameterError(f'speed_px_s must be positive, got {speed_px_s}')
        scene = replace(scene, speed_dps=speed_px_s / px_per_degree(base[0]))
    if make:
        base = [base[0]] + [replace(c, **make) for c in base[1:]]
    clocks = _clocks(rng, len(base), skew=(name == 'drift'))
    cams = tuple(replace(c, **k) for c, k in zip(base, clocks))
    if triggers_hz < 0:
        raise ParameterError(f'triggers_hz must be 0 (none) or positive, got {triggers_hz}')
    return Rig(cameras=cams, scene=scene, seed=seed, triggers=TriggerTrain(hz=triggers_hz) if triggers_hz else None)
