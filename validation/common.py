"""Shared helpers of the validation experiments: scenes, cameras, captures, error figures, provenance.

Everything here is numpy; Mitsuba is reached only through :func:`scenes.render` and the
synthetic camera only through :func:`synth.capture`.  No function prints, plots or exits.

Error figures follow the paper: RMSE in percent of the DN range,
``100 * rmse / (white_level - black_level)``, over a pixel mask (the validity mask of the
emulated image) and over all pixels.
"""

from __future__ import annotations

import hashlib
import math
import os
import sys
from dataclasses import dataclass

import numpy as np

from emulator.errors import ExposimError
from synth.sequence import BRACKETS_MS

__all__ = [
    "BRACKETS_MS",
    "PAPER_MEDIAN_RMSE_PERCENT",
    "PAPER_MAX_RMSE_PERCENT",
    "SHOT_INTERVAL_MS",
    "RESPONSES",
    "StudyScene",
    "STUDY_SCENES",
    "ValidationError",
    "study_scene",
    "gt_exposures",
    "seed_for",
    "make_camera",
    "camera_summary",
    "camera_vignetting",
    "static_radiance",
    "capture",
    "rmse_dn",
    "to_percent",
    "pair_noise_map",
    "subtract_quadrature",
    "subtract_linear",
    "quantisation_bound",
    "summary_stats",
    "provenance",
    "Progress",
]

#: Paper section V-B: median and maximum emulation RMSE over five static test sequences.
PAPER_MEDIAN_RMSE_PERCENT = 0.21
PAPER_MAX_RMSE_PERCENT = 1.78
#: One shot every ~46 ms at 22 frames/s (DESIGN.md, "Recordings").
SHOT_INTERVAL_MS = 1000.0 / 22.0
#: Camera responses of the synthetic camera (``synth.Camera.preset`` names).
RESPONSES: tuple[str, ...] = ("borealhdr", "linear", "gamma22", "s_curve")


class ValidationError(ExposimError):
    """A validation configuration is invalid (unknown scene, bad size, too few repeats ...)."""


# ---------------------------------------------------------------------------------- scenes
@dataclass(frozen=True)
class StudyScene:
    """One static scene of the study: a registered scene, its parameters and where the camera stands.

    Attributes
    ----------
    key : str
        Name used in results (unique).
    scene : str
        :func:`scenes.get_scene` name.
    params : dict
        Scene parameters (overrides of the defaults).
    lighting : str
        ``"indoor"`` or ``"outdoor"`` (the paper validated both).
    pose_time_s : float or None
        Timestamp of the scene's default trajectory where the static camera stands
        (None: the scene's default pose).
    seed : int
        Scene seed (placement and textures).
    """

    key: str
    scene: str
    params: tuple = ()
    lighting: str = "outdoor"
    pose_time_s: float | None = None
    seed: int = 0

    def build(self):
        import scenes

        return scenes.get_scene(self.scene, seed=self.seed, **dict(self.params))

    def pose(self, scene=None) -> np.ndarray:
        scene = scene or self.build()
        if self.pose_time_s is None:
            return scene.default_pose()
        return scene.trajectory(duration_s=max(1.0, self.pose_time_s + 1.0)).pose(self.pose_time_s)


#: The static scenes of the emulation study: two indoor (lamp-lit lab, normal and dim) and
#: four outdoor; sun_glare and forest_edge exceed 100 dB.
STUDY_SCENES: dict[str, StudyScene] = {
    s.key: s
    for s in (
        StudyScene("static_lab", "static_lab", lighting="indoor"),
        StudyScene("static_lab_dim", "static_lab", (("light_irradiance_w_m2", 60.0),), lighting="indoor", seed=1),
        StudyScene("forest_winter", "forest_winter"),
        StudyScene("forest_summer", "forest_summer"),
        StudyScene("sun_glare", "sun_glare"),
        StudyScene("forest_edge", "forest_edge", pose_time_s=45.0),
    )
}


def study_scene(key: str) -> StudyScene:
    """The :class:`StudyScene` called ``key``; refuses an unknown name with the valid ones."""
    try:
        return STUDY_SCENES[key]
    except KeyError:
        raise ValidationError(f"unknown study scene {key!r}; choose from {', '.join(STUDY_SCENES)}") from None


def static_radiance(key: str, *, width: int, height: int, spp: int, seed: int = 0, cache_dir=None) -> np.ndarray:
    """Render study scene ``key`` from its static pose (through the render cache).

    Returns float32 (height, width, 3) linear radiance, W m^-2 sr^-1.
    """
    import scenes

    spec = study_scene(key)
    scene = spec.build()
    return scenes.render(scene, spec.pose(scene), width=width, height=height, spp=spp, seed=seed,
                         cache_dir=cache_dir)


# ---------------------------------------------------------------------------------- exposures and seeds
def gt_exposures(n: int, lo_ms: float = 0.02, hi_ms: float = 50.0) -> np.ndarray:
    """``n`` ground-truth exposure times log-spaced from ``lo_ms`` to ``hi_ms`` (float64, ms)."""
    if isinstance(n, bool) or int(n) != n or n < 2:
        raise ValidationError(f"number of exposures must be an integer >= 2, got {n!r}")
    if not (0 < lo_ms < hi_ms and math.isfinite(hi_ms)):
        raise ValidationError(f"need 0 < lo_ms < hi_ms, got {lo_ms!r}, {hi_ms!r}")
    return np.geomspace(float(lo_ms), float(hi_ms), int(n))


def seed_for(*keys) -> int:
    """A 32-bit seed derived deterministically from integers and strings (stable across runs)."""
    h = hashlib.sha256(repr(tuple(keys)).encode()).digest()
    return int.from_bytes(h[:4], "little")


# ---------------------------------------------------------------------------------- camera
def make_camera(response: str = "borealhdr", vignetting: float | None = None, *, width: int, height: int):
    """A ``synth.Camera`` preset of the image size, optionally with another vignetting strength.

    Parameters
    ----------
    response : str
        Preset name: one of :data:`RESPONSES`.
    vignetting : float or None
        ``vignetting_strength`` of the camera (cos^4 model); None keeps the preset's.
    width, height : int
        Image size (pixels): the radiance the camera captures must have this shape.
    """
    import synth

    if response not in RESPONSES:
        raise ValidationError(f"unknown camera response {response!r}; choose from {', '.join(RESPONSES)}")
    overrides = {"width": int(width), "height": int(height)}
    if vignetting is not None:
        overrides["vignetting_strength"] = float(vignetting)
    return synth.Camera.preset(response, **overrides)


def camera_vignetting(cam) -> float:
    """The camera's vignetting strength."""
    return float(cam.vignetting_strength)


def camera_summary(cam) -> dict:
    """JSON-ready description of a camera (``synth.Camera.to_dict``)."""
    return cam.to_dict()


def capture(radiance: np.ndarray, exposure_ms: float, camera, *, seed: int, noise: bool = True) -> np.ndarray:
    """One raw capture through the synthetic camera (``synth.capture``): uint16 (H, W) DN."""
    import synth

    return synth.capture(radiance, float(exposure_ms), camera, seed=int(seed), noise=bool(noise))


# ---------------------------------------------------------------------------------- error figures
def rmse_dn(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None) -> float | None:
    """RMSE in DN between two images over ``mask`` (all pixels if None); None for an empty mask."""
    d = a.astype(np.float64) - b.astype(np.float64)
    if mask is not None:
        if not mask.any():
            return None
        d = d[mask]
    return float(np.sqrt(np.mean(d * d)))


def to_percent(rmse, white_level: int, black_level: int):
    """DN -> percent of the DN range ``white_level - black_level`` (None stays None; arrays allowed)."""
    if rmse is None:
        return None
    return 100.0 * np.asarray(rmse, dtype=np.float64) / float(white_level - black_level) if isinstance(
        rmse, np.ndarray) else 100.0 * float(rmse) / float(white_level - black_level)


def pair_noise_map(captures) -> np.ndarray:
    """Per-pixel noise variance (DN^2, float64) from repeated captures of one exposure.

    Estimator: for consecutive captures ``c_i, c_{i+1}`` (independent noise, same mean),
    ``E[(c_{i+1} - c_i)^2] = 2 sigma^2``; the map is the mean over the ``n - 1`` pairs of
    ``(c_{i+1} - c_i)^2 / 2``.  Unbiased for the per-pixel variance, and blind to the fixed
    image content (the paper's "error between consecutive images").
    """
    caps = [np.asarray(c, dtype=np.float64) for c in captures]
    if len(caps) < 2:
        raise ValidationError(f"noise estimation needs at least 2 repeated captures, got {len(caps)}")
    acc = np.zeros_like(caps[0])
    for a, b in zip(caps[:-1], caps[1:]):
        d = b - a
        acc += d * d
    return acc / (2.0 * (len(caps) - 1))


def subtract_quadrature(rmse, sigma):
    """``sqrt(max(rmse^2 - sigma^2, 0))``: remove independent ground-truth noise of std ``sigma``."""
    if rmse is None or sigma is None:
        return None
    return float(math.sqrt(max(rmse * rmse - sigma * sigma, 0.0)))


def subtract_linear(rmse, noise):
    """``max(rmse - noise, 0)``: the paper's phrasing ("subtract this noise")."""
    if rmse is None or noise is None:
        return None
    return float(max(rmse - noise, 0.0))


def quantisation_bound(response, src: np.ndarray, ratio: float) -> np.ndarray:
    """Per-pixel analytic bound (DN, float64) of the noiseless emulation error.

    A source DN ``d`` stands for any linear exposure in ``[g(d - 1/2), g(d + 1/2)]``;
    scaled by the ratio ``k`` and mapped through ``f`` that interval holds the true target,
    while the emulator returns ``f(k g(d))``.  The error is at most the larger distance
    from ``f(k g(d))`` to the ends ``f(k g(d -+ 1/2))``, plus one rounding (1 DN: the
    emulator's and the capture's rounding, each at most 1/2).  Valid wherever the source
    was not clipped, and for clips the ratio preserves (the validity mask).
    """
    d = src.astype(np.float64)
    top = float(response.white_level)
    lo = response.forward(ratio * response.inverse(np.clip(d - 0.5, 0.0, top)))
    hi = response.forward(ratio * response.inverse(np.clip(d + 0.5, 0.0, top)))
    mid = response.forward(ratio * response.inverse(d))
    return np.maximum(hi - mid, mid - lo) + 1.0


def summary_stats(values) -> dict:
    """Median, mean, 95th percentile, max and count of the finite values (None when empty)."""
    a = np.asarray([v for v in values if v is not None], dtype=np.float64)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return {"median": None, "mean": None, "p95": None, "max": None, "n": 0}
    return {"median": float(np.median(a)), "mean": float(np.mean(a)), "p95": float(np.percentile(a, 95)),
            "max": float(np.max(a)), "n": int(a.size)}


# ---------------------------------------------------------------------------------- output
def provenance(command: str, config: dict) -> dict:
    """What produced a results file: experiment, configuration, versions (no timestamps: deterministic)."""
    import emulator

    versions = {"exposim": getattr(emulator, "__version__", "?"), "numpy": np.__version__,
                "python": ".".join(map(str, sys.version_info[:3]))}
    return {"experiment": command, "config": config, "versions": versions}


class Progress:
    """A callback wrapper: ``Progress(cb)(n)`` calls ``cb(n)`` when a callback was given."""

    def __init__(self, callback=None):
        self.callback = callback

    def __call__(self, n: int = 1) -> None:
        if self.callback is not None:
            self.callback(n)


def env_flag(name: str) -> bool:
    return os.environ.get(name, "").strip() not in ("", "0", "false", "no")
