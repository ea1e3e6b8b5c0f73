"""Samples per pixel from a noise target instead of a fixed number.

Monte Carlo rendering adds noise that the synthetic camera would then treat as
scene texture.  It is harmless once it is well below the sensor's own temporal
noise, and the sensor is least noisy (relative to the signal) at the brightest
bracket, so that is where the target is set.

Model.  With a gain that brings a white Lambertian surface facing the main
light (the scene's ``reference_radiance``) to full well at the shortest bracket
(``saturation_exposure_ms``, 1 ms), a pixel of radiance L collects
``S = FWC * (L / L_ref) * (t / t_sat)`` electrons at exposure t.  Its sensor
variance is ``S + read_noise**2`` (shot plus read noise), and the render's
variance, scaled the same way, is ``(S / L)**2 * var(L)``.  The *noise ratio*
is the square root of the summed render variance over the summed sensor
variance, over the pixels that are not saturated at the brightest bracket.
``var(L)`` is estimated per pixel from two renders with different seeds:
``(L_a - L_b)**2 / 2``.  :func:`select_spp` returns the smallest candidate spp
with a ratio at or below the target, and the whole curve.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from scenes.errors import RenderError

__all__ = ["SensorNoise", "SppSelection", "measure_render_noise", "select_spp", "DEFAULT_CANDIDATES"]

#: Candidate spp, roughly doubling, all taken exactly by the stratified sampler.
DEFAULT_CANDIDATES = (1, 2, 4, 9, 16, 36, 64, 144, 256, 576, 1024)


@dataclass(frozen=True)
class SensorNoise:
    """Temporal noise of the sensor at one exposure.

    Attributes
    ----------
    full_well_e : float
        Full-well capacity, electrons.  Default: the order of the Sony IMX392
        in the BorealHDR Basler a2A1920-51gcPRO (about 10 ke-); use the synthetic
        camera's value when it exists.
    read_noise_e : float
        Read noise, electrons rms (IMX392: about 2-3 e-).
    exposure_ms : float
        Exposure at which the target is set: the brightest bracket, 32 ms.
    saturation_exposure_ms : float
        Exposure at which ``reference_radiance`` fills the well (the shortest
        bracket, 1 ms: the brackets then cover sunlit white to deep shade).
    """

    full_well_e: float = 10_000.0
    read_noise_e: float = 2.5
    exposure_ms: float = 32.0
    saturation_exposure_ms: float = 1.0

    def __post_init__(self) -> None:
        for k in ("full_well_e", "exposure_ms", "saturation_exposure_ms"):
            v = getattr(self, k)
            if not (math.isfinite(v) and v > 0):
                raise RenderError(f"SensorNoise.{k} must be a finite number > 0, got {v!r}")
        if not (math.isfinite(self.read_noise_e) and self.read_noise_e >= 0):
            raise RenderError(f"SensorNoise.read_noise_e must be >= 0, got {self.read_noise_e!r}")

    def electrons_per_radiance(self, reference_radiance: float) -> float:
        """Gain at ``exposure_ms``: electrons per W m^-2 sr^-1."""
        if not reference_radiance > 0:
            raise RenderError(f"reference_radiance must be > 0, got {reference_radiance!r}")
        return self.full_well_e / reference_radiance * self.exposure_ms / self.saturation_exposure_ms


@dataclass
class SppSelection:
    """Result of :func:`select_spp`.

    Attributes
    ----------
    spp : int
        Smallest candidate whose noise ratio is at or below ``target_ratio``
        (the largest candidate when none is: see ``met``).
    met : bool
        Whether some candidate met the target.
    target_ratio : float
        Render noise / sensor noise target (1: render noise below sensor noise).
    predicted_spp : int
        spp the variance-proportional-to-1/spp law predicts for the target, from
        the largest candidate measured (useful when the target is out of reach
        of the candidates; the stratified sampler converges a little faster, so
        this errs on the high side).
    curve : list of dict
        One row per candidate: ``spp``, ``noise_ratio``, ``render_noise_rel``
        (rms render noise / mean signal over the unsaturated pixels),
        ``sensor_noise_rel`` (the same for the sensor), ``pixels`` (values used).
    """

    spp: int
    met: bool
    target_ratio: float
    predicted_spp: int
    curve: list = field(default_factory=list)
    sensor: dict = field(default_factory=dict)
    width: int = 0
    height: int = 0

    def to_dict(self) -> dict:
        return asdict(self)


def measure_render_noise(
    scene,
    pose,
    *,
    width: int,
    height: int,
    spp: int,
    sensor: SensorNoise | None = None,
    seeds: tuple[int, int] = (1, 2),
    **render_kwargs,
) -> dict:
    """Noise of renders at one spp, against the sensor's noise (see the module notes).

    Parameters
    ----------
    scene, pose, width, height, spp
        As for :func:`scenes.render`.
    sensor : SensorNoise, optional
        Sensor model (default :class:`SensorNoise`).
    seeds : tuple of int
        Two different sampler seeds.
    **render_kwargs
        Passed to :func:`scenes.render` (``fov_deg``, ``variant``, ``cache_dir``).

    Returns
    -------
    dict
        ``spp``, ``noise_ratio``, ``render_noise_rel``, ``sensor_noise_rel``, ``pixels``.
    """
    from scenes.render import effective_spp, render

    spp = effective_spp(int(spp))
    sensor = sensor or SensorNoise()
    if len(seeds) != 2 or seeds[0] == seeds[1]:
        raise RenderError(f"seeds must be two different integers, got {seeds!r}")
    a = render(scene, pose, width=width, height=height, spp=spp, seed=seeds[0], **render_kwargs)
    b = render(scene, pose, width=width, height=height, spp=spp, seed=seeds[1], **render_kwargs)
    gain = sensor.electrons_per_radiance(scene.reference_radiance)
    a64, b64 = a.astype(np.float64).ravel(), b.astype(np.float64).ravel()
    mean = 0.5 * (a64 + b64)
    var = 0.5 * (a64 - b64) ** 2
    signal = gain * mean
    mask = (signal > 0) & (signal < sensor.full_well_e)
    n = int(mask.sum())
    if n == 0:
        return {"spp": int(spp), "noise_ratio": float("nan"), "render_noise_rel": float("nan"),
                "sensor_noise_rel": float("nan"), "pixels": 0}
    render_var_e = gain**2 * var[mask]
    sensor_var_e = signal[mask] + sensor.read_noise_e**2
    mean_signal = float(signal[mask].mean())
    return {
        "spp": int(spp),
        "noise_ratio": float(math.sqrt(render_var_e.sum() / sensor_var_e.sum())),
        "render_noise_rel": float(math.sqrt(render_var_e.mean()) / mean_signal),
        "sensor_noise_rel": float(math.sqrt(sensor_var_e.mean()) / mean_signal),
        "pixels": n,
    }


def select_spp(
    scene,
    pose,
    *,
    width: int,
    height: int,
    candidates=DEFAULT_CANDIDATES,
    target_ratio: float = 1.0,
    sensor: SensorNoise | None = None,
    seeds: tuple[int, int] = (1, 2),
    stop_when_met: bool = True,
    **render_kwargs,
) -> SppSelection:
    """Smallest spp whose render noise stays below the sensor noise at the brightest bracket.

    Parameters
    ----------
    scene, pose, width, height
        As for :func:`scenes.render` (measure at the size you will render).
    candidates : iterable of int
        spp values to try, in increasing order (each rounded as the sampler
        rounds it, see :func:`scenes.render.effective_spp`).
    target_ratio : float
        Largest acceptable render-noise / sensor-noise ratio (rms, electrons).
    sensor : SensorNoise, optional
        Sensor model (default :class:`SensorNoise`: brightest bracket 32 ms).
    seeds : tuple of int
        Two sampler seeds for the noise estimate.
    stop_when_met : bool
        Stop at the first candidate that meets the target (else measure all).
    **render_kwargs
        Passed to :func:`scenes.render` (``fov_deg``, ``variant``, ``cache_dir``;
        default ``cache_dir=False``).

    Returns
    -------
    SppSelection
        The choice and the spp-vs-noise curve.
    """
    from scenes.render import effective_spp

    cands = [int(c) for c in candidates]
    if not cands or any(c < 1 for c in cands) or cands != sorted(set(cands)):
        raise RenderError(f"candidates must be increasing positive integers, got {candidates!r}")
    cands = sorted({effective_spp(c) for c in cands})
    if not (math.isfinite(target_ratio) and target_ratio > 0):
        raise RenderError(f"target_ratio must be > 0, got {target_ratio!r}")
    sensor = sensor or SensorNoise()
    render_kwargs.setdefault("cache_dir", False)
    curve = []
    chosen = None
    for c in cands:
        row = measure_render_noise(scene, pose, width=width, height=height, spp=c, sensor=sensor, seeds=seeds,
                                   **render_kwargs)
        curve.append(row)
        if chosen is None and math.isfinite(row["noise_ratio"]) and row["noise_ratio"] <= target_ratio:
            chosen = c
            if stop_when_met:
                break
    last = curve[-1]
    ratio = last["noise_ratio"]
    predicted = int(math.ceil(last["spp"] * (ratio / target_ratio) ** 2)) if math.isfinite(ratio) else last["spp"]
    return SppSelection(spp=chosen if chosen is not None else cands[-1], met=chosen is not None,
                        target_ratio=float(target_ratio), predicted_spp=max(1, predicted), curve=curve,
                        sensor=asdict(sensor), width=int(width), height=int(height))
