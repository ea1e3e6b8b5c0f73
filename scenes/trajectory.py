"""Camera trajectories: a walking person with a head-mounted stereo rig.

A trajectory maps a timestamp (seconds) to a 4x4 camera-to-world pose of the
left camera in the OpenCV camera frame (x right, y down, z forward); the world
frame has z up and the ground at z = 0.  :func:`stereo_right` gives the right
camera of the rig.  On disk, poses use the TUM format that evo reads
(:mod:`emulator.io.tum`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from scenes.errors import SceneError

__all__ = [
    "WALKING_SPEED_MPS",
    "BASELINE_M",
    "Trajectory",
    "walk",
    "stream_key",
    "static",
    "look_pose",
    "stereo_right",
    "rotation_matrices",
]

#: 2 km/h, the BorealHDR walking pace, in m/s.
WALKING_SPEED_MPS = 2.0 / 3.6

_GAUSS_LEGENDRE = np.polynomial.legendre.leggauss(32)

#: Stereo baseline of the BorealHDR rig (paper section V-A), metres.
BASELINE_M = 0.18


def _rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Camera-to-world rotation (OpenCV camera frame) for a heading, pitch and roll (radians).

    yaw: optical axis heading in the ground plane, from +x towards +y.
    pitch: positive looks up.  roll: positive turns the image clockwise about the optical axis.
    """
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    forward = np.array([cp * cy, cp * sy, sp])
    left_h = np.array([-sy, cy, 0.0])
    right = -left_h
    down = np.cross(forward, right)  # z x x = y in a right-handed frame
    r = np.stack([right, down, forward], axis=1)
    if roll:
        cr, sr = math.cos(roll), math.sin(roll)
        r = r @ np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    return r


def rotation_matrices(yaw, pitch, roll) -> np.ndarray:
    """Camera-to-world rotations (OpenCV camera frame) for arrays of heading, pitch and roll (radians),
    broadcast together: float64 (N, 3, 3); :func:`_rotation` for one pose."""
    yaw, pitch, roll = np.broadcast_arrays(*(np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (yaw, pitch, roll)))
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    forward = np.stack([cp * cy, cp * sy, sp], axis=-1)
    right = np.stack([sy, -cy, np.zeros_like(sy)], axis=-1)
    down = np.cross(forward, right)
    r = np.stack([right, down, forward], axis=-1)
    cr, sr = np.cos(roll), np.sin(roll)
    z, o = np.zeros_like(cr), np.ones_like(cr)
    spin = np.stack([np.stack([cr, -sr, z], -1), np.stack([sr, cr, z], -1), np.stack([z, z, o], -1)], axis=-2)
    return r @ spin


def look_pose(position, heading_deg: float, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
    """4x4 camera-to-world pose at ``position`` looking along a heading.

    Parameters
    ----------
    position : array-like
        (3,) camera centre, metres.
    heading_deg : float
        Direction of the optical axis in the ground plane, degrees from +x to +y.
    pitch_deg : float
        Elevation of the optical axis, degrees (negative looks down).
    roll_deg : float
        Rotation about the optical axis, degrees.
    """
    m = np.eye(4)
    m[:3, :3] = _rotation(math.radians(heading_deg), math.radians(pitch_deg), math.radians(roll_deg))
    m[:3, 3] = np.asarray(position, dtype=np.float64)
    return m


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A smooth camera path, evaluated analytically at any timestamp.

    Attributes
    ----------
    duration_s : float
        Valid timestamps are 0 .. duration_s.
    start : tuple of float
        (x, y) at t = 0, metres.
    heading_deg : float
        Initial walking direction, degrees from +x towards +y.
    speed_mps : float
        Horizontal speed along the path (constant), m/s.
    height_m : float
        Mean camera height above the ground, metres.
    bob_amplitude_m : float
        Vertical head bob amplitude, metres (0: no bob).
    step_frequency_hz : float
        Steps per second; the bob has this frequency, head sway half of it.
    pitch_deg : float
        Mean pitch of the optical axis, degrees (negative looks down).
    sway_deg : float
        Amplitude of the head's pitch and roll oscillation, degrees.
    turn_deg : float
        Amplitude of the slow meander of the walking direction, degrees.
    turn_period_s : float
        Period of the meander, seconds.
    phases : tuple of float
        Random phases (radians) of bob, sway and meander, from the seed.
    """

    duration_s: float
    start: tuple = (0.0, 0.0)
    heading_deg: float = 0.0
    speed_mps: float = WALKING_SPEED_MPS
    height_m: float = 1.6
    bob_amplitude_m: float = 0.015
    step_frequency_hz: float = 1.5
    pitch_deg: float = -5.0
    sway_deg: float = 0.5
    turn_deg: float = 4.0
    turn_period_s: float = 40.0
    phases: tuple = (0.0, 0.0, 0.0, 0.0)
    is_static: bool = False
    fixed_pose: np.ndarray | None = field(default=None, repr=False)

    def _check_t(self, t: float) -> float:
        t = float(t)
        if not (math.isfinite(t) and -1e-9 <= t <= self.duration_s + 1e-9):
            raise SceneError(f"timestamp_s must be in [0, {self.duration_s}] s, got {t!r}")
        return t

    def heading_rad(self, t):
        """Walking direction at time t (scalar or array), radians: initial heading plus a slow meander."""
        w = 2.0 * math.pi / self.turn_period_s
        return math.radians(self.heading_deg) + math.radians(self.turn_deg) * (
            np.sin(w * np.asarray(t, dtype=np.float64) + self.phases[2]) - math.sin(self.phases[2])
        )

    def position_xy(self, t: float) -> np.ndarray:
        """Horizontal position at t: the integral of ``speed * (cos h, sin h)`` from 0 to t.

        With ``h(t) = h0 + A (sin(w t + p) - sin p)`` the integral has no
        elementary closed form; it is evaluated with a 32-node Gauss-Legendre
        rule on every quarter of the meander period, accurate to far below a
        micrometre for the default parameters.
        """
        if t <= 0.0:
            return np.asarray(self.start, dtype=np.float64)
        nodes, weights = _GAUSS_LEGENDRE
        segments = max(1, int(math.ceil(t / (self.turn_period_s / 4.0))))
        edges = np.linspace(0.0, t, segments + 1)
        half = 0.5 * (edges[1:] - edges[:-1])[:, None]
        ts = half * nodes[None, :] + 0.5 * (edges[1:] + edges[:-1])[:, None]
        h = self.heading_rad(ts)
        total = np.array([np.sum(half * weights * np.cos(h)), np.sum(half * weights * np.sin(h))])
        return np.asarray(self.start, dtype=np.float64) + self.speed_mps * total

    def pose(self, timestamp_s: float) -> np.ndarray:
        """4x4 camera-to-world pose (float64, OpenCV camera frame) of the left camera."""
        t = self._check_t(timestamp_s)
        if self.is_static:
            return np.array(self.fixed_pose, dtype=np.float64)
        xy = self.position_xy(t)
        step = 2.0 * math.pi * self.step_frequency_hz * t
        z = self.height_m + self.bob_amplitude_m * math.sin(step + self.phases[0])
        stride = 0.5 * step  # the head sways once per stride (two steps)
        pitch = self.pitch_deg + self.sway_deg * math.sin(step + self.phases[1])
        roll = self.sway_deg * math.sin(stride + self.phases[3])
        yaw = float(self.heading_rad(t))
        m = np.eye(4)
        m[:3, :3] = _rotation(yaw, math.radians(pitch), math.radians(roll))
        m[:3, 3] = (xy[0], xy[1], z)
        return m

    def poses(self, timestamps_s) -> np.ndarray:
        """Poses at many timestamps: float64 (N, 4, 4)."""
        return np.stack([self.pose(t) for t in np.atleast_1d(timestamps_s)])

    def timestamps(self, rate_hz: float) -> np.ndarray:
        """Timestamps 0, 1/rate, ... up to ``duration_s`` (float64 seconds)."""
        if not rate_hz > 0:
            raise SceneError(f"rate_hz must be > 0, got {rate_hz!r}")
        n = int(math.floor(self.duration_s * rate_hz + 1e-9)) + 1
        return np.arange(n) / float(rate_hz)


def walk(
    duration_s: float,
    speed_mps: float = WALKING_SPEED_MPS,
    height_m: float = 1.6,
    bob_amplitude_m: float = 0.015,
    *,
    seed: int = 0,
    start: tuple = (0.0, 0.0),
    heading_deg: float = 0.0,
    step_frequency_hz: float = 1.5,
    pitch_deg: float = -5.0,
    sway_deg: float = 0.5,
    turn_deg: float = 4.0,
    turn_period_s: float = 40.0,
    stream: str = "",
) -> Trajectory:
    """A smooth walk at constant horizontal speed with a small head bob.

    Parameters
    ----------
    duration_s : float
        Length of the trajectory, seconds (> 0).
    speed_mps : float
        Horizontal walking speed, m/s (default 2 km/h, the BorealHDR pace).
    height_m : float
        Mean camera height, metres (default 1.6: head-mounted).
    bob_amplitude_m : float
        Vertical bob amplitude at the step frequency, metres (slow walk: 1-2 cm).
    seed : int
        Phases of the bob, sway and meander.
    start : tuple of float
        (x, y) start, metres.
    heading_deg : float
        Initial walking direction, degrees from +x towards +y.
    step_frequency_hz : float
        Cadence, steps per second (about 1.5 at 2 km/h).
    pitch_deg : float
        Mean pitch of the optical axis, degrees (negative looks down).
    sway_deg : float
        Amplitude of head pitch (per step) and roll (per stride), degrees.
    turn_deg, turn_period_s : float
        Amplitude (degrees) and period (s) of the slow meander of the heading.
    stream : str
        Name mixed into the random stream with ``seed`` (a scene's walk passes the scene's
        name, so two scenes with one seed do not share their motion); empty: the stream of
        ``seed`` alone (what walks were before the scene joined it).

    Returns
    -------
    Trajectory
    """
    for name, v, lo in (("duration_s", duration_s, 0.0), ("speed_mps", speed_mps, -1e-12),
                        ("height_m", height_m, 0.0), ("turn_period_s", turn_period_s, 0.0)):
        if not (math.isfinite(float(v)) and float(v) > lo):
            raise SceneError(f"walk: {name} must be a finite number > {max(lo, 0)}, got {v!r}")
    if not 0.0 <= bob_amplitude_m < height_m:
        raise SceneError(f"walk: bob_amplitude_m must be in [0, height_m), got {bob_amplitude_m!r}")
    rng = np.random.default_rng(stream_key(seed, 7, stream))
    phases = tuple(float(p) for p in rng.uniform(0.0, 2.0 * math.pi, 4))
    return Trajectory(duration_s=float(duration_s), start=(float(start[0]), float(start[1])),
                      heading_deg=float(heading_deg), speed_mps=float(speed_mps), height_m=float(height_m),
                      bob_amplitude_m=float(bob_amplitude_m), step_frequency_hz=float(step_frequency_hz),
                      pitch_deg=float(pitch_deg), sway_deg=float(sway_deg), turn_deg=float(turn_deg),
                      turn_period_s=float(turn_period_s), phases=phases)


def stream_key(seed: int, purpose: int, stream: str = "") -> list[int]:
    """Entropy of a random stream: ``[seed, purpose]``, plus a CRC-32 of ``stream`` when it is not empty."""
    import zlib

    key = [int(seed), int(purpose)]
    return key + [zlib.crc32(stream.encode("utf-8"))] if stream else key


def static(pose, duration_s: float = 1.0) -> Trajectory:
    """A camera that does not move: the same pose at every timestamp in [0, duration_s]."""
    from scenes.camera import check_pose

    m = check_pose(pose)
    if not (math.isfinite(float(duration_s)) and duration_s >= 0):
        raise SceneError(f"static: duration_s must be >= 0, got {duration_s!r}")
    return Trajectory(duration_s=float(duration_s), speed_mps=0.0, bob_amplitude_m=0.0, is_static=True,
                      fixed_pose=m.copy(), start=(float(m[0, 3]), float(m[1, 3])), height_m=float(m[2, 3]))


def stereo_right(pose, baseline_m: float = BASELINE_M) -> np.ndarray:
    """Pose of the right camera of a stereo rig from the left camera's pose.

    The right camera has the same orientation, translated by ``+baseline_m``
    along the left camera's x axis (to its right in the image).

    Parameters
    ----------
    pose : array-like
        4x4 camera-to-world pose of the left camera (OpenCV frame).
    baseline_m : float
        Distance between the optical centres, metres (BorealHDR: 0.18).
    """
    from scenes.camera import check_pose

    m = check_pose(pose).copy()
    m[:3, 3] = m[:3, 3] + float(baseline_m) * m[:3, 0]
    return m
