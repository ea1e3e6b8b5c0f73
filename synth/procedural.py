"""Procedural HDR radiance without Mitsuba: a textured test chart and a camera sliding past it.

For tests, demos and benchmarks that need radiance spanning many stops, with texture
that feature detectors (SIFT) find, and motion between bracket shots, without rendering.

* :func:`hdr_chart`: a grid of patches whose mean radiances are log-spaced over a chosen
  dynamic range, each modulated by band-limited fractal texture and a few rectangles,
  with dark grid lines between patches.
* :class:`TranslatingChart`: a radiance source for :func:`synth.capture_sequence`; a
  fronto-parallel chart at ``depth_m`` in front of a (stereo) camera that walks sideways
  at ``speed_m_s``.  The pose is a pure translation, so the image is the chart shifted by
  ``f * x / depth`` pixels (sub-pixel shifts interpolated linearly).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from synth.presets import BOREALHDR_FOV_X_DEG, REFERENCE_RADIANCE
from synth.errors import SourceError, SynthError

__all__ = ["hdr_chart", "TranslatingChart", "WALK_SPEED_M_S"]

#: About 2 km/h (DESIGN.md, "Scenes").
WALK_SPEED_M_S = 2.0 / 3.6


def _fractal(shape: tuple[int, int], rng: np.random.Generator, *, octaves: int = 5, base_cells: int = 4) -> np.ndarray:
    """Band-limited noise in [0, 1], float32 (H, W): a sum of upsampled random grids, stretched."""
    h, w = shape
    acc = np.zeros(shape, dtype=np.float32)
    total = 0.0
    for o in range(octaves):
        cells = base_cells * 2**o
        gh = max(2, int(round(cells * h / max(h, w))) + 1)
        gw = max(2, int(round(cells * w / max(h, w))) + 1)
        grid = rng.random((gh, gw), dtype=np.float32)
        amp = 0.75**o
        acc += amp * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
        total += amp
    acc /= total
    # stretch +-2 standard deviations to [0, 1]: a sum of octaves crowds around its mean
    acc -= float(acc.mean())
    acc *= 0.25 / max(float(acc.std()), 1e-6)
    acc += 0.5
    return np.clip(acc, 0.0, 1.0, out=acc)


def hdr_chart(
    width: int,
    height: int,
    seed: int = 0,
    *,
    dynamic_range_db: float = 100.0,
    max_radiance: float = REFERENCE_RADIANCE,
    patch_px: int | None = None,
    texture_contrast: float = 0.5,
) -> np.ndarray:
    """A textured HDR test chart.

    Parameters
    ----------
    width, height : int
        Size in pixels (>= 4 each).
    seed : int
        Seed of the layout, levels and texture (same seed, same chart).
    dynamic_range_db : float
        Ratio of the brightest to the darkest patch mean, ``20 log10`` (100 dB = 5 decades).
    max_radiance : float
        Mean radiance of the brightest patch, W m^-2 sr^-1 (default: white paper facing a
        1000 W m^-2 sun, which fills a preset camera's well at 1 ms).
    patch_px : int or None
        Patch side in pixels; None picks about 1/8 of the shorter side (at least 8).
    texture_contrast : float
        Texture modulates each patch by a factor in ``[1 - c, 1 + c]`` (0 <= c < 1).

    Returns
    -------
    ndarray, float32 (height, width, 3)
        Linear RGB radiance, W m^-2 sr^-1, all values > 0.  Patch means are log-spaced
        from ``max_radiance`` down by ``dynamic_range_db`` and shuffled; each patch has a
        mild random tint (+-15 % per channel); the grid lines between patches are dimmed
        to 10 % of the patch they lie in.
    """
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 4:
            raise SynthError(f"{name} must be an integer >= 4, got {v!r}")
    if not (math.isfinite(dynamic_range_db) and dynamic_range_db >= 0):
        raise SynthError(f"dynamic_range_db must be finite and >= 0, got {dynamic_range_db!r}")
    if not (math.isfinite(max_radiance) and max_radiance > 0):
        raise SynthError(f"max_radiance must be finite and > 0, got {max_radiance!r}")
    if not 0.0 <= texture_contrast < 1.0:
        raise SynthError(f"texture_contrast must be in [0, 1), got {texture_contrast!r}")
    rng = np.random.default_rng(seed)
    side = patch_px if patch_px is not None else max(8, min(width, height) // 8)
    if isinstance(side, bool) or not isinstance(side, (int, np.integer)) or side < 4:
        raise SynthError(f"patch_px must be an integer >= 4, got {patch_px!r}")
    rows, cols = -(-height // side), -(-width // side)
    n = rows * cols
    levels = max_radiance * 10.0 ** (-dynamic_range_db / 20.0 * np.linspace(0.0, 1.0, n))
    levels = rng.permutation(levels).reshape(rows, cols)
    tint = 1.0 + 0.15 * (2.0 * rng.random((rows, cols, 3)) - 1.0)
    patch = np.repeat(np.repeat(levels[..., None] * tint, side, 0), side, 1)[:height, :width]

    texture = _fractal((height, width), rng, base_cells=max(2, -(-max(height, width) // side)))
    # a few flat rectangles per patch: corners for feature detectors
    n_rect = 3 * n
    y0 = rng.integers(0, height, n_rect)
    x0 = rng.integers(0, width, n_rect)
    hh = rng.integers(max(2, side // 8), max(3, side // 3), n_rect)
    ww = rng.integers(max(2, side // 8), max(3, side // 3), n_rect)
    val = rng.random(n_rect)
    for a, b, c, d, v in zip(y0, x0, hh, ww, val):
        texture[a: a + c, b: b + d] = v
    modulation = (1.0 - texture_contrast) + 2.0 * texture_contrast * texture
    out = patch * modulation[..., None]
    # grid lines one pixel wide (two on larger charts), at 10 % of the patch
    lw = 1 if side < 32 else 2
    for k in range(side, height, side):
        out[k - lw: k] *= 0.1
    for k in range(side, width, side):
        out[:, k - lw: k] *= 0.1
    return np.ascontiguousarray(out, dtype=np.float32)


class TranslatingChart:
    """A (stereo) camera walking sideways past a textured HDR chart: a radiance source.

    Call it as ``source(timestamp_s, camera)`` with ``camera`` ``"left"`` or ``"right"``;
    it returns ``(radiance float32 (H, W, 3), pose float64 4x4)``.  The world frame is
    the left camera's frame at t = 0 (x right, y down, z forward); the chart is the plane
    z = ``depth_m``; the left camera is at ``(speed_m_s * t, 0, 0)`` and the right one
    ``baseline_m`` further along x (same orientation), as :func:`synth.capture_sequence`
    expects of a stereo rig.

    Parameters
    ----------
    width, height : int
        Image size, pixels (the camera's).
    seed : int
        Chart seed.
    speed_m_s : float
        Walking speed along x, m/s (default about 2 km/h); 0 gives a static scene.
    depth_m : float
        Distance to the chart, m.
    baseline_m : float
        Stereo baseline, m (BorealHDR: 0.18).
    fov_x_deg : float
        Horizontal field of view, degrees (the camera's ``fov_x_deg``).
    duration_s : float
        Longest timestamp served, s; the chart is generated wide enough for it.
    **chart
        Passed to :func:`hdr_chart` (``dynamic_range_db``, ``max_radiance``, ...).
    """

    def __init__(
        self,
        width: int,
        height: int,
        *,
        seed: int = 0,
        speed_m_s: float = WALK_SPEED_M_S,
        depth_m: float = 5.0,
        baseline_m: float = 0.18,
        fov_x_deg: float = BOREALHDR_FOV_X_DEG,
        duration_s: float = 10.0,
        **chart,
    ) -> None:
        for name, v, lo in (("speed_m_s", speed_m_s, 0.0), ("baseline_m", baseline_m, 0.0),
                            ("duration_s", duration_s, 0.0)):
            if not (math.isfinite(v) and v >= lo):
                raise SynthError(f"{name} must be finite and >= {lo:g}, got {v!r}")
        if not (math.isfinite(depth_m) and depth_m > 0):
            raise SynthError(f"depth_m must be finite and > 0, got {depth_m!r}")
        if not 0 < fov_x_deg < 180:
            raise SynthError(f"fov_x_deg must be in (0, 180), got {fov_x_deg!r}")
        self.width, self.height = int(width), int(height)
        self.speed_m_s, self.depth_m, self.baseline_m = float(speed_m_s), float(depth_m), float(baseline_m)
        self.duration_s = float(duration_s)
        self.focal_length_px = (self.width / 2.0) / math.tan(math.radians(fov_x_deg) / 2.0)
        self.pixels_per_m = self.focal_length_px / self.depth_m
        travel = self.pixels_per_m * (self.speed_m_s * self.duration_s + self.baseline_m)
        self.chart = hdr_chart(self.width + int(math.ceil(travel)) + 2, self.height, seed, **chart)
        self.seed = int(seed)
        self._chart_args = dict(chart)

    def describe(self) -> dict:
        """JSON-ready description (written to the dataset's metadata)."""
        return {
            "type": "synth.procedural.TranslatingChart",
            "width": self.width,
            "height": self.height,
            "seed": self.seed,
            "speed_m_s": self.speed_m_s,
            "depth_m": self.depth_m,
            "baseline_m": self.baseline_m,
            "duration_s": self.duration_s,
            "focal_length_px": self.focal_length_px,
            "chart": self._chart_args,
        }

    def pose(self, timestamp_s: float, camera: str = "left") -> np.ndarray:
        """Camera-to-world pose (float64 4x4) of ``camera`` at ``timestamp_s``."""
        if camera not in ("left", "right"):
            raise SourceError(f"camera must be 'left' or 'right', got {camera!r}")
        m = np.eye(4)
        m[0, 3] = self.speed_m_s * float(timestamp_s) + (self.baseline_m if camera == "right" else 0.0)
        return m

    def __call__(self, timestamp_s: float, camera: str = "left") -> tuple[np.ndarray, np.ndarray]:
        pose = self.pose(timestamp_s, camera)
        if not 0.0 <= float(timestamp_s) <= self.duration_s:
            raise SourceError(
                f"timestamp {timestamp_s!r} s is outside the chart's [0, {self.duration_s:g}] s "
                "(raise duration_s)"
            )
        shift = self.pixels_per_m * pose[0, 3]
        i = int(math.floor(shift))
        a = np.float32(shift - i)
        left = self.chart[:, i: i + self.width]
        if a == 0:
            return left.copy(), pose
        right = self.chart[:, i + 1: i + 1 + self.width]
        return (left * (1 - a) + right * a).astype(np.float32), pose
