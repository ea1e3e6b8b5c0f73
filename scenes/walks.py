"""Walks that turn like the real one: a seeded gait model and a replay of a recorded gyro.

The BorealHDR backpack recording (``imu/imu.csv`` of the shared sample, 100 Hz, 200 s)
turns at a median 10.7 deg/s, p90 18.2, p99 27.2; its gyro spectrum has one line per
harmonic of the stride frequency (0.79 Hz: pitch peaks at the step frequency 1.57 Hz,
yaw at the stride frequency, roll at its third harmonic), slow head turns below 0.35 Hz
and a broadband rest.  The gentle walk of :func:`scenes.trajectory.walk` (0.5 deg sway)
turns at 3.8 deg/s.

:class:`GaitWalk` (the preset ``"borealhdr"``, the default walk of every scene) draws,
from its seed, a sum of sinusoids per rotation axis whose band powers are those measured
on that gyro (:data:`GYRO_BAND_RMS_DEG_S`): each harmonic band is a set of lines spread
by a 3 % cadence jitter, the slow band is spread over 0.05-0.35 Hz, the broadband rest
over 0.35-8 Hz.  Angles are the exact integrals of the rates, so any instant can be
evaluated.  The body walks at 2 km/h along the slow meander of the gentle walk; the head
bobs at the step frequency and sways sideways at the stride frequency.

:class:`GyroReplay` replays a recorded gyro: the orientation is the integral of the
recorded rates (mean removed by default, so a recording that turns steadily does not walk
the camera off the scene's path) and the translation is the gentle walk's.

Frames: camera x right, y down, z forward (OpenCV); the IMU frame of the files written by
:func:`synth` (and read here) is x forward, y left, z up (:data:`CAMERA_FROM_IMU`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from scenes.errors import SceneError

__all__ = [
    "GAIT_STEP_HZ",
    "GYRO_BAND_RMS_DEG_S",
    "CAMERA_FROM_IMU",
    "GaitWalk",
    "GyroReplay",
    "gait_walk",
    "gyro_replay",
    "read_gyro_csv",
    "poses_of",
    "angular_velocity",
    "imu_samples",
    "WALK_PRESETS",
    "DEFAULT_WALK",
    "make_walk",
]

#: Step frequency of the BorealHDR sample's walk, Hz (peak of the gyro's pitch spectrum,
#: Welch, 8192-sample segments); the stride (one left and one right step) is half of it.
GAIT_STEP_HZ = 1.575

#: RMS angular rate (deg/s) of the BorealHDR sample's gyro per axis and band, measured with
#: Welch (4096-sample segments, mean removed): ``low`` below 0.35 Hz, ``k`` in 1..8 the
#: stride harmonic k (+-0.2 Hz), ``rest`` everything else.  Axes of the IMU frame: roll
#: about x forward, pitch about y left, yaw about z up.
GYRO_BAND_RMS_DEG_S = {
    "roll": {"low": 1.02, "harmonics": (1.41, 1.12, 2.64, 1.40, 1.21, 1.76, 1.06, 1.00), "rest": 2.62},
    "pitch": {"low": 0.73, "harmonics": (1.65, 5.98, 1.21, 2.49, 0.54, 1.17, 0.17, 0.12), "rest": 2.55},
    "yaw": {"low": 5.15, "harmonics": (5.48, 2.16, 2.10, 1.25, 0.74, 0.46, 0.36, 0.18), "rest": 2.44},
}

#: Rotation taking IMU-frame vectors (x forward, y left, z up) to the camera frame
#: (x right, y down, z forward): ``omega_camera = CAMERA_FROM_IMU @ omega_imu``.
CAMERA_FROM_IMU = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])

_LINES_PER_BAND = 16
_LOW_BAND_HZ = (0.05, 0.35)
_REST_BAND_HZ = (0.35, 8.0)
_CADENCE_JITTER_FRACTION = 0.03
_BODY_GRID_S = 0.05
_ENVELOPE_HZ = 0.08


class _BodyPath:
    """The gentle walk's meandering path without head motion, vectorised over time.

    Positions are tabulated every :data:`_BODY_GRID_S` by the trapezoid rule on the
    analytic heading and continued from the nearest node with the mid-point heading
    (error far below a micrometre: the heading turns over tens of seconds).
    """

    def __init__(self, duration_s, start, heading_deg, speed_mps, seed, stream=""):
        from scenes.trajectory import walk

        self.path = walk(duration_s, speed_mps=speed_mps, bob_amplitude_m=0.0, seed=seed, start=start,
                         heading_deg=heading_deg, sway_deg=0.0, pitch_deg=0.0, stream=stream)
        n = int(math.ceil(duration_s / _BODY_GRID_S)) + 1
        self.grid = np.arange(n) * _BODY_GRID_S
        h = self.path.heading_rad(self.grid)
        seg = 0.5 * _BODY_GRID_S * speed_mps * np.stack([np.cos(h[1:]) + np.cos(h[:-1]),
                                                          np.sin(h[1:]) + np.sin(h[:-1])], axis=1)
        self.xy = np.asarray(start, dtype=np.float64) + np.concatenate([np.zeros((1, 2)), np.cumsum(seg, axis=0)])
        self.speed = float(speed_mps)

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """((N, 2) positions, (N,) headings in rad) at times t."""
        k = np.clip(np.floor(t / _BODY_GRID_S).astype(int), 0, len(self.grid) - 1)
        dt = t - self.grid[k]
        hm = self.path.heading_rad(self.grid[k] + 0.5 * dt)
        xy = self.xy[k] + self.speed * dt[:, None] * np.stack([np.cos(hm), np.sin(hm)], axis=1)
        return xy, self.path.heading_rad(t)


def _head_pose(body: _BodyPath, t: np.ndarray, yaw_rad, pitch_rad, roll_rad, z_m, lateral_m) -> np.ndarray:
    """(N, 4, 4) head poses: body position and heading plus head angles and offsets."""
    from scenes.trajectory import rotation_matrices

    xy, heading = body.at(t)
    out = np.zeros((t.size, 4, 4))
    out[:, 3, 3] = 1.0
    out[:, :3, :3] = rotation_matrices(heading + yaw_rad, pitch_rad, roll_rad)
    out[:, 0, 3] = xy[:, 0] - lateral_m * np.sin(heading)
    out[:, 1, 3] = xy[:, 1] + lateral_m * np.cos(heading)
    out[:, 2, 3] = z_m
    return out


def _modulate(w, a, p, m: float, q: float):
    """Lines of ``(1 + m sin(W t + q)) * sum a sin(w t + p)``, rms kept (W = 2 pi _ENVELOPE_HZ).

    ``a sin(x) m sin(y) = a m / 2 (sin(x - y + pi/2) + sin(x + y - pi/2))``.
    """
    big_w = 2.0 * math.pi * _ENVELOPE_HZ
    slow = w < 2.0 * math.pi * _REST_BAND_HZ[0] - 1e-12  # the slow head turns are not modulated
    ws, as_, ps = w[~slow], a[~slow] / math.sqrt(1.0 + 0.5 * m * m), p[~slow]
    return (np.concatenate([w[slow], ws, ws - big_w, ws + big_w]),
            np.concatenate([a[slow], as_, 0.5 * m * as_, 0.5 * m * as_]),
            np.concatenate([p[slow], ps, ps - q + 0.5 * math.pi, ps + q - 0.5 * math.pi]))


class _Timed:
    """Shared by the walks: timestamp checks, ``pose``, ``timestamps``."""

    duration_s: float
    is_static = False

    def _check_times(self, timestamps_s) -> np.ndarray:
        t = np.atleast_1d(np.asarray(timestamps_s, dtype=np.float64))
        if not np.all(np.isfinite(t)) or np.any(t < -1e-9) or np.any(t > self.duration_s + 1e-9):
            raise SceneError(f"timestamp_s must be in [0, {self.duration_s}] s, got {timestamps_s!r}")
        return np.clip(t, 0.0, self.duration_s)

    def pose(self, timestamp_s: float) -> np.ndarray:
        """4x4 camera-to-world pose (float64, OpenCV camera frame) of the left camera."""
        return self.poses([timestamp_s])[0]

    def timestamps(self, rate_hz: float) -> np.ndarray:
        """Timestamps 0, 1/rate, ... up to ``duration_s`` (float64 seconds)."""
        if not rate_hz > 0:
            raise SceneError(f"rate_hz must be > 0, got {rate_hz!r}")
        n = int(math.floor(self.duration_s * rate_hz + 1e-9)) + 1
        return np.arange(n) / float(rate_hz)


@dataclass(frozen=True, eq=False)
class GaitWalk(_Timed):
    """A walk whose head turns like the BorealHDR backpack's (see the module docstring).

    Attributes
    ----------
    duration_s : float
        Valid timestamps are 0 .. duration_s.
    start, heading_deg, speed_mps : as :func:`scenes.trajectory.walk`
        The body's path (the gentle walk's meander, no head motion).
    height_m, pitch_deg : float
        Mean camera height (m) and pitch of the optical axis (deg, negative looks down).
    step_frequency_hz : float
        Steps per second; the rate harmonics are multiples of half of it (the stride).
    rate_scale : float
        Multiplies every band's rate (1: the measured walk).
    bob_amplitude_m, lateral_sway_m : float
        Head bob (step frequency) and sideways sway (stride frequency) amplitudes, m.
    intensity_modulation : float
        Depth m of the slow (:data:`_ENVELOPE_HZ`) swell of the whole gait's rate,
        ``1 + m sin(...)``, rms kept: a walker alternates calm and lively stretches, which
        gives the rate distribution the real one's long tail (p99 / p50 = 2.55; a stationary
        sum of lines gives about 2.3).
    seed : int
        Seed of the lines' frequencies and phases.
    stream : str
        Name mixed into the seed's random stream (a scene's walk: the scene's name); empty:
        the stream of the seed alone (walks before the scene joined it).
    """

    duration_s: float
    start: tuple = (0.0, 0.0)
    heading_deg: float = 0.0
    speed_mps: float = 2.0 / 3.6
    height_m: float = 1.6
    pitch_deg: float = -5.0
    step_frequency_hz: float = GAIT_STEP_HZ
    rate_scale: float = 1.0
    bob_amplitude_m: float = 0.02
    lateral_sway_m: float = 0.015
    intensity_modulation: float = 0.3
    seed: int = 0
    stream: str = ""
    _lines: dict = field(default=None, repr=False)

    def __post_init__(self) -> None:
        from scenes.trajectory import stream_key

        rng = np.random.default_rng(stream_key(self.seed, 21, self.stream))
        stride = 0.5 * self.step_frequency_hz
        lines = {}
        for axis in ("roll", "pitch", "yaw"):
            bands = GYRO_BAND_RMS_DEG_S[axis]
            freqs, amps = [], []
            for rms, f in [(bands["low"], rng.uniform(*_LOW_BAND_HZ, _LINES_PER_BAND)),
                           (bands["rest"], rng.uniform(*_REST_BAND_HZ, _LINES_PER_BAND))] + [
                    (r, (k + 1) * stride * (1.0 + _CADENCE_JITTER_FRACTION * rng.standard_normal(_LINES_PER_BAND)))
                    for k, r in enumerate(bands["harmonics"])]:
                freqs.append(f)
                amps.append(np.full(_LINES_PER_BAND, math.radians(rms) * self.rate_scale
                                    * math.sqrt(2.0 / _LINES_PER_BAND)))
            lines[axis] = (2.0 * math.pi * np.concatenate(freqs), np.concatenate(amps),
                           rng.uniform(0.0, 2.0 * math.pi, len(freqs) * _LINES_PER_BAND))
        phases = rng.uniform(0.0, 2.0 * math.pi, 3)
        lines = {axis: _modulate(*wap, self.intensity_modulation, phases[2]) for axis, wap in lines.items()}
        object.__setattr__(self, "_lines", {"axes": lines, "phases": phases,
                                            "body": _BodyPath(self.duration_s, self.start, self.heading_deg,
                                                               self.speed_mps, self.seed, self.stream)})

    def angles_rad(self, t: np.ndarray) -> dict:
        """Head yaw, pitch and roll offsets (rad) at times t: integrals of the rate lines, zero at their mean."""
        out = {}
        for axis, (w, a, p) in self._lines["axes"].items():
            out[axis] = np.concatenate([-np.cos(np.multiply.outer(chunk, w) + p) @ (a / w)
                                        for chunk in np.array_split(t, max(1, t.size // 2048))])
        return out

    def poses(self, timestamps_s) -> np.ndarray:
        """Poses at many timestamps: float64 (N, 4, 4)."""
        t = self._check_times(timestamps_s)
        ang = self.angles_rad(t)
        step = 2.0 * math.pi * self.step_frequency_hz * t
        p_bob, p_sway = self._lines["phases"][:2]
        z = self.height_m + self.bob_amplitude_m * np.sin(step + p_bob)
        lateral = self.lateral_sway_m * np.sin(0.5 * step + p_sway)
        # yaw about z up = heading increase; pitch about y left is nose down, so it enters negated
        return _head_pose(self._lines["body"], t, ang["yaw"], math.radians(self.pitch_deg) - ang["pitch"],
                          ang["roll"], z, lateral)


def gait_walk(duration_s: float, *, seed: int = 0, speed_mps: float = 2.0 / 3.6, start: tuple = (0.0, 0.0),
              heading_deg: float = 0.0, **kwargs) -> GaitWalk:
    """The realistic walk (preset ``"borealhdr"``): see :class:`GaitWalk` for the parameters."""
    for name, v in (("duration_s", duration_s), ("speed_mps", speed_mps)):
        if not (math.isfinite(float(v)) and float(v) >= 0 and (name != "duration_s" or float(v) > 0)):
            raise SceneError(f"gait_walk: {name} must be a finite number > 0, got {v!r}")
    rate_scale = float(kwargs.get("rate_scale", 1.0))
    if not (math.isfinite(rate_scale) and rate_scale >= 0):
        raise SceneError(f"gait_walk: rate_scale must be >= 0, got {rate_scale!r}")
    return GaitWalk(duration_s=float(duration_s), seed=int(seed), speed_mps=float(speed_mps),
                    start=(float(start[0]), float(start[1])), heading_deg=float(heading_deg), **kwargs)


def read_gyro_csv(path) -> tuple[np.ndarray, np.ndarray]:
    """(timestamps in s from the first sample, rates (N, 3) rad/s in the IMU frame) of a BorealHDR ``imu.csv``.

    Parsed by :func:`emulator.io.imu.parse_imu` (a malformed file is a ``DatasetError`` naming the line).
    """
    from pathlib import Path

    from emulator.io.files import read_text
    from emulator.io.imu import parse_imu

    p = Path(path)
    if not p.is_file():
        raise SceneError(f"{p}: no such gyro file")
    imu = parse_imu(read_text(p), p)
    if len(imu) < 2:
        raise SceneError(f"{p}: needs at least two samples")
    t_ns = imu.timestamp_ns
    return (t_ns - t_ns[0]).astype(np.float64) * 1e-9, np.asarray(imu.gyro_rad_s, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class GyroReplay(_Timed):
    """A walk whose orientation replays recorded gyro rates (piecewise constant between samples).

    ``rotations`` holds the camera-to-world rotation at every sample; between samples the
    camera turns at the sample's rate.  The position is the gentle walk's body path.
    """

    duration_s: float
    sample_times_s: np.ndarray = field(repr=False, default=None)
    camera_rates: np.ndarray = field(repr=False, default=None)
    rotations: np.ndarray = field(repr=False, default=None)
    body: object = field(repr=False, default=None)
    height_m: float = 1.6

    def poses(self, timestamps_s) -> np.ndarray:
        from scipy.spatial.transform import Rotation

        t = self._check_times(timestamps_s)
        k = np.clip(np.searchsorted(self.sample_times_s, t, side="right") - 1, 0, len(self.sample_times_s) - 1)
        dt = t - self.sample_times_s[k]
        step = Rotation.from_rotvec(self.camera_rates[k] * dt[:, None]).as_matrix()
        out = np.zeros((t.size, 4, 4))
        out[:, 3, 3] = 1.0
        out[:, :3, :3] = self.rotations[k] @ step
        out[:, :2, 3] = self.body.at(t)[0]
        out[:, 2, 3] = self.height_m
        return out


def gyro_replay(path, *, duration_s: float | None = None, start_s: float = 0.0, remove_mean: bool = True,
                seed: int = 0, speed_mps: float = 2.0 / 3.6, start: tuple = (0.0, 0.0), heading_deg: float = 0.0,
                pitch_deg: float = -5.0, height_m: float = 1.6) -> GyroReplay:
    """A walk that replays the gyro of a BorealHDR ``imu.csv`` from ``start_s`` (s after its first sample).

    The rates (IMU frame x forward, y left, z up) are turned into the camera frame with
    :data:`CAMERA_FROM_IMU` and integrated from a level pose looking along ``heading_deg``
    (pitched by ``pitch_deg``).  ``remove_mean`` subtracts the mean rate of the replayed
    window (a steady turn or a gyro bias), so the walk stays on the scene's path.
    """
    from scipy.spatial.transform import Rotation

    from scenes.trajectory import look_pose

    t, omega = read_gyro_csv(path)
    if not 0.0 <= start_s < t[-1]:
        raise SceneError(f"gyro_replay: start_s must be in [0, {t[-1]:.3f}) s, got {start_s!r}")
    end = t[-1] if duration_s is None else start_s + float(duration_s)
    if not (end <= t[-1] + 1e-9 and end > start_s):
        raise SceneError(f"gyro_replay: duration_s must be > 0 and end by {t[-1] - start_s:.3f} s, got {duration_s!r}")
    keep = (t >= start_s - 1e-12) & (t <= end)
    ts, w = t[keep] - start_s, omega[keep]
    if remove_mean:
        w = w - w.mean(axis=0)
    cam = w @ CAMERA_FROM_IMU.T
    steps = Rotation.from_rotvec(cam[:-1] * np.diff(ts)[:, None]).as_matrix()
    rot = np.empty((ts.size, 3, 3))
    rot[0] = look_pose((0.0, 0.0, 0.0), heading_deg, pitch_deg)[:3, :3]
    for i in range(1, ts.size):
        rot[i] = rot[i - 1] @ steps[i - 1]
    body = _BodyPath(end - start_s, start, heading_deg, speed_mps, seed)
    return GyroReplay(duration_s=float(end - start_s), sample_times_s=ts, camera_rates=cam, rotations=rot,
                      body=body, height_m=float(height_m))


def poses_of(traj, timestamps_s) -> np.ndarray:
    """(N, 4, 4) poses of any trajectory (vectorised where it offers ``poses``)."""
    return np.asarray(traj.poses(np.atleast_1d(np.asarray(timestamps_s, dtype=np.float64))), dtype=np.float64)


def angular_velocity(traj, timestamps_s, *, step_s: float = 5e-4) -> np.ndarray:
    """Angular velocity of the camera, rad/s, in the camera frame: float64 (N, 3).

    Central difference of the rotation over ``2 * step_s`` (one-sided at the ends of the
    trajectory): ``log(R(t - h)^T R(t + h)) / 2h``.  Works for every trajectory
    (:class:`GaitWalk`, :class:`GyroReplay`, :class:`scenes.trajectory.Trajectory`).
    """
    from scipy.spatial.transform import Rotation

    t = np.atleast_1d(np.asarray(timestamps_s, dtype=np.float64))
    lo = np.clip(t - step_s, 0.0, traj.duration_s)
    hi = np.clip(t + step_s, 0.0, traj.duration_s)
    if np.any(hi - lo <= 0):
        raise SceneError("angular_velocity: the trajectory is too short to differentiate")
    r0, r1 = poses_of(traj, lo)[:, :3, :3], poses_of(traj, hi)[:, :3, :3]
    rel = np.einsum("nji,njk->nik", r0, r1)
    return Rotation.from_matrix(rel).as_rotvec() / (hi - lo)[:, None]


def imu_samples(traj, rate_hz: float = 100.0, *, t0_s: float = 0.0, t1_s: float | None = None,
                gravity_mps2: float = 9.80665) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A synthetic IMU riding with the left camera, in the IMU frame (x forward, y left, z up).

    Returns
    -------
    times_s : numpy.ndarray
        (N,) sample times, s, from ``t0_s`` to ``t1_s`` (default the trajectory's end) at ``rate_hz``.
    gyro : numpy.ndarray
        (N, 3) angular velocity, rad/s (:func:`angular_velocity` turned by ``CAMERA_FROM_IMU.T``).
    accel : numpy.ndarray
        (N, 3) specific force, m/s^2: the second difference of the position plus gravity
        (world z up), in the IMU frame (at rest: +9.81 on z).
    """
    end = traj.duration_s if t1_s is None else float(t1_s)
    if not rate_hz > 0 or not 0.0 <= t0_s < end <= traj.duration_s + 1e-9:
        raise SceneError(f"imu_samples: need rate_hz > 0 and 0 <= t0_s < t1_s <= {traj.duration_s}")
    t = t0_s + np.arange(int(math.floor((end - t0_s) * rate_hz + 1e-9)) + 1) / float(rate_hz)
    gyro = angular_velocity(traj, t) @ CAMERA_FROM_IMU
    h = 5e-3
    centre = np.clip(t, min(h, 0.5 * traj.duration_s), max(traj.duration_s - h, 0.5 * traj.duration_s))
    p = [poses_of(traj, np.clip(centre + d, 0.0, traj.duration_s)) for d in (-h, 0.0, h)]
    acc_world = (p[2][:, :3, 3] - 2.0 * p[1][:, :3, 3] + p[0][:, :3, 3]) / (h * h)
    p[1] = poses_of(traj, t)
    acc_world[:, 2] += gravity_mps2
    acc_cam = np.einsum("nji,nj->ni", p[1][:, :3, :3], acc_world)
    return t, gyro, acc_cam @ CAMERA_FROM_IMU


#: Walk presets of :meth:`scenes.Scene.trajectory` (``walk=``); ``"replay:PATH"`` replays a gyro file.
WALK_PRESETS = ("borealhdr", "gentle")
#: The default walk of every scene, of ``exposim synth`` and of the studies.
DEFAULT_WALK = "borealhdr"


def make_walk(walk: str, duration_s: float, **kwargs):
    """A walk by preset name: ``"borealhdr"`` (:func:`gait_walk`), ``"gentle"``
    (:func:`scenes.trajectory.walk`, the 0.5 deg sway of earlier versions) or
    ``"replay:PATH"`` (:func:`gyro_replay` of a BorealHDR ``imu.csv``).

    ``kwargs`` (``seed``, ``speed_mps``, ``start``, ``heading_deg``, ...) go to the builder.
    """
    from scenes.trajectory import walk as gentle

    if not isinstance(walk, str):
        raise SceneError(f"walk must be a preset name ({', '.join(WALK_PRESETS)}) or 'replay:PATH', got {walk!r}")
    if walk == "borealhdr":
        return gait_walk(duration_s, **kwargs)
    if walk == "gentle":
        return gentle(duration_s, **kwargs)
    if walk.startswith("replay:"):
        keep = {k: v for k, v in kwargs.items() if k in ("seed", "speed_mps", "start", "heading_deg")}
        return gyro_replay(walk[len("replay:"):], duration_s=duration_s, **keep)
    raise SceneError(f"unknown walk {walk!r}; choose from {', '.join(WALK_PRESETS)} or 'replay:PATH'")
