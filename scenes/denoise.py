"""Denoising low-spp renders with Intel Open Image Denoise (OIDN), CPU device.

A path tracer's noise is not something a camera sees: it invents keypoints and
gradients that are not in the scene and differ between two renders of one pose.
So the default render path is a low-spp estimate of the radiance plus two
auxiliary images of the first hit, the albedo (diffuse reflectance) and the
shading normal, rendered by Mitsuba's ``aov`` integrator, passed through OIDN's
``RT`` filter (Áfra 2024) in HDR mode.  ``denoise="off"`` gives the raw estimate.

Choices, each part of the render cache key (:meth:`DenoiseSettings.key_material`):

``aux_spp``
    The albedo and normal are rendered in their own pass (primary rays only, about a
    tenth of the cost of one path-traced sample) at ``max(spp, aux_spp)`` samples, so
    they are anti-aliased and practically noise-free; ``clean_aux=True`` then tells
    OIDN not to prefilter them, which keeps texture detail the noisy colour cannot
    carry (OIDN documentation, "RT filter": auxiliary images should be as noise-free
    as possible; ``cleanAux`` when they are).
``hdr_scale``
    OIDN reads HDR colour so that ``value * hdrScale == 1`` is a luminance of
    100 cd/m^2.  Scene radiance is in W m^-2 sr^-1 with RGB scaled to luminance, and
    daylight carries about 100 lm/W, so one unit is about 100 cd/m^2 and the scale is
    1.  Fixing it (instead of OIDN's per-image automatic scale) keeps the network's
    view of a surface the same from frame to frame, which matters for flicker.
``quality``
    OIDN's ``high`` quality (its default for offline rendering).

The very bright: OIDN's HDR transfer function is defined up to 65504 (half float); a
directly seen sun disk reaches 1e7.  Pixels whose raw radiance exceeds
:data:`PASSTHROUGH_RADIANCE` (in units of the scene's reference radiance, a white
surface facing the sun) are the sun disk, its specular glints and nothing else in
these scenes; they are handed to OIDN clipped to that level and put back at their raw
value afterwards, so the denoiser can neither clip them nor spread their energy over
the neighbourhood (see the render study's hard cases).

Determinism: on this machine OIDN's CPU device gives the same bytes across runs,
processes and thread counts (1 or 2; measured).  Its kernels are chosen per CPU
instruction set, so another CPU may differ in the last bits: the render cache, which
stores the bytes once, is the source of truth.

Missing ``pyoidn``, a library that does not load, or a CPU OIDN does not support (it
needs x86-64 with SSE4.1 or ARM64) is reported once per process as a
:class:`DenoiserUnavailableWarning` and the render falls back to the raw estimate
(cached under the raw key, so it is never mistaken for a denoised image).

References
----------
Áfra, A. T. (2024). Intel Open Image Denoise. https://www.openimagedenoise.org
"""

from __future__ import annotations

import math
import os
import threading
import warnings
from dataclasses import asdict, dataclass, replace
from importlib import metadata

import numpy as np

from scenes.errors import RenderError

__all__ = [
    "DENOISERS",
    "DENOISER_PRESETS",
    "DEFAULT_DENOISER",
    "ENV_DENOISE",
    "default_denoiser",
    "PASSTHROUGH_RADIANCE",
    "DenoiseSettings",
    "DenoiserUnavailableWarning",
    "resolve_denoise",
    "effective_denoise",
    "oidn_status",
    "oidn_version",
    "denoise_oidn",
]

#: Valid values of ``denoise=`` (besides a :class:`DenoiseSettings`).
DENOISERS = ("oidn", "oidn-fast", "oidn-hq", "off")
#: The settings each named denoiser stands for (besides its name).  ``oidn-fast`` trades a
#: little error for time: OIDN's ``balanced`` filter and a 16-spp albedo/normal pass
#: (forest_winter, 480x300, 2 spp: 0.55 s and 3.1 % against 1.2 s and 2.7 % for ``oidn``;
#: see the render study).  ``oidn-hq`` spends time for features: a 1024-spp albedo/normal pass,
#: whose own sampling noise otherwise stays in the denoised image; with 256 spp it is the setting
#: whose render noise costs SIFT no more than the sensor's (docs/results/render.md).
DENOISER_PRESETS = {"oidn": {}, "oidn-fast": {"quality": "balanced", "aux_spp": 16}, "oidn-hq": {"aux_spp": 1024}}
#: What every render uses unless told otherwise (or ``$EXPOSIM_DENOISE`` says otherwise).
DEFAULT_DENOISER = "oidn"
#: Environment variable naming the denoiser of renders that do not name one (``oidn`` or ``off``).
ENV_DENOISE = "EXPOSIM_DENOISE"
#: Raw radiance above this many times the scene's reference radiance bypasses the denoiser.
PASSTHROUGH_RADIANCE = 8.0
#: OIDN's HDR input is encoded up to this value (times hdrScale).
_OIDN_HDR_MAX = 65504.0

_QUALITIES = ("fast", "balanced", "high")


class DenoiserUnavailableWarning(RuntimeWarning):
    """OIDN cannot run here: renders fall back to the raw estimate."""


@dataclass(frozen=True)
class DenoiseSettings:
    """How a render is denoised.

    Attributes
    ----------
    name : str
        ``"oidn"``, ``"oidn-fast"``, ``"oidn-hq"`` (presets of :data:`DENOISER_PRESETS`) or ``"off"``.
    quality : str
        OIDN filter quality: ``"fast"``, ``"balanced"`` or ``"high"``.
    hdr_scale : float or None
        OIDN ``hdrScale`` (1: one radiance unit is 100 cd/m^2); None lets OIDN pick
        a scale per image.
    aux_spp : int
        Samples per pixel of the albedo / normal pass (at least the colour's spp).
    clean_aux : bool
        Tell OIDN the auxiliary images are noise-free (no prefiltering).
    passthrough : float
        Raw radiance above ``passthrough * reference_radiance`` keeps its raw value
        (0 disables it).
    """

    name: str = DEFAULT_DENOISER
    quality: str = "high"
    hdr_scale: float | None = 1.0
    aux_spp: int = 64
    clean_aux: bool = True
    passthrough: float = PASSTHROUGH_RADIANCE

    def __post_init__(self) -> None:
        if self.name not in DENOISERS:
            raise RenderError(f"unknown denoiser {self.name!r}; valid: {', '.join(DENOISERS)}")
        if self.quality not in _QUALITIES:
            raise RenderError(f"denoise quality must be one of {', '.join(_QUALITIES)}, got {self.quality!r}")
        if self.hdr_scale is not None and not (math.isfinite(self.hdr_scale) and self.hdr_scale > 0):
            raise RenderError(f"hdr_scale must be None or > 0, got {self.hdr_scale!r}")
        if isinstance(self.aux_spp, bool) or not isinstance(self.aux_spp, (int, np.integer)) or not (
                1 <= self.aux_spp <= 4096):
            raise RenderError(f"aux_spp must be an integer in [1, 4096], got {self.aux_spp!r}")
        if not (math.isfinite(self.passthrough) and self.passthrough >= 0):
            raise RenderError(f"passthrough must be >= 0, got {self.passthrough!r}")

    @property
    def enabled(self) -> bool:
        return self.name != "off"

    def key_material(self) -> dict:
        """Denoiser name, version and settings, as they enter the render cache key."""
        if not self.enabled:
            return {"name": "off"}
        return {"name": self.name, "version": oidn_version(), "settings": asdict(self)}


def default_denoiser() -> str:
    """The denoiser of renders that do not name one: ``$EXPOSIM_DENOISE`` if set, else :data:`DEFAULT_DENOISER`.

    Like ``$EXPOSIM_MITSUBA_VARIANT`` for the variant: a way to run whole studies (or
    tests that are not about rendering) on raw renders without a parameter on every
    study.  The choice enters the render cache key like an explicit ``denoise=``.

    Raises
    ------
    RenderError
        The variable names an unknown denoiser.
    """
    name = os.environ.get(ENV_DENOISE, "").strip()
    if not name:
        return DEFAULT_DENOISER
    if name not in DENOISERS:
        raise RenderError(f"${ENV_DENOISE}={name!r} is not a denoiser; valid: {', '.join(DENOISERS)}")
    return name


def resolve_denoise(denoise) -> DenoiseSettings:
    """``"oidn"`` / ``"oidn-fast"`` / ``"off"`` / a :class:`DenoiseSettings` (or None: :func:`default_denoiser`) -> settings.

    Raises
    ------
    RenderError
        Unknown name (the message lists the valid ones) or wrong type.
    """
    if denoise is None:
        denoise = default_denoiser()
    if isinstance(denoise, DenoiseSettings):
        return denoise
    if isinstance(denoise, str):
        if denoise not in DENOISERS:
            raise RenderError(f"unknown denoiser {denoise!r}; valid: {', '.join(DENOISERS)}")
        return DenoiseSettings(name=denoise, **DENOISER_PRESETS.get(denoise, {}))
    raise RenderError(f"denoise must be one of {', '.join(DENOISERS)} or a DenoiseSettings, got {denoise!r}")


def effective_denoise(denoise) -> tuple[DenoiseSettings, str | None]:
    """The settings a render will actually use, and why OIDN is not used when it was asked for.

    Resolves ``denoise`` like :func:`resolve_denoise`; when it names OIDN and OIDN cannot
    run here (missing ``pyoidn``, a library that does not load, an unsupported CPU),
    warns once (:class:`DenoiserUnavailableWarning`) and returns ``(off settings, reason)``.
    Never raises for an unavailable denoiser.

    Returns
    -------
    settings : DenoiseSettings
    fallback : str or None
        The reason for the fallback, None when none happened.
    """
    settings = resolve_denoise(denoise)
    if not settings.enabled:
        return settings, None
    ok, reason = oidn_status()
    if ok:
        return settings, None
    warn_unavailable(reason)
    return DenoiseSettings(name="off"), reason


def oidn_version() -> dict:
    """Versions of the OIDN library and of its ``pyoidn`` binding (from metadata; 'missing' if absent)."""
    try:
        binding = metadata.version("pyoidn")
    except metadata.PackageNotFoundError:
        binding = "missing"
    # pyoidn's version is the OIDN version plus a binding revision (2.5.1.0 wraps OIDN 2.5.1)
    library = ".".join(binding.split(".")[:3]) if binding != "missing" else "missing"
    return {"oidn": library, "pyoidn": binding}


# ------------------------------------------------------------------------------ the device
_lock = threading.RLock()
_state: dict = {}


def _reset() -> None:
    """Forget the probed device (tests simulate a missing library with it)."""
    with _lock:
        flt = _state.get("filter")
        dev = _state.get("device")
        if flt is not None:
            flt.release()
        if dev is not None:
            dev.release()
        _state.clear()


def _open():
    """(pyoidn module, committed CPU device, RT filter) or raise RuntimeError with the reason."""
    try:
        import pyoidn
    except ImportError as exc:
        raise RuntimeError(f"the pyoidn package is not installed ({exc}); pip install pyoidn") from None
    except OSError as exc:  # the shared library did not load
        raise RuntimeError(f"the OIDN library did not load ({exc})") from None
    if not pyoidn.Device.is_cpu_available():
        raise RuntimeError("OIDN does not support this CPU (it needs x86-64 with SSE4.1, or ARM64)")
    device = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
    error = device.get_error()
    if error:
        raise RuntimeError(f"OIDN could not create a CPU device: {error}")
    device.commit()
    error = device.get_error()
    if error:
        device.release()
        raise RuntimeError(f"OIDN could not start its CPU device: {error}")
    flt = pyoidn.Filter(device, pyoidn.OIDN_FILTER_TYPE_RT)
    error = device.get_error()
    if error:
        device.release()
        raise RuntimeError(f"OIDN could not create its RT filter: {error}")
    return pyoidn, device, flt


def oidn_status() -> tuple[bool, str]:
    """(usable, reason) for the OIDN CPU device; probed once per process.

    Never raises: a missing package, a library that fails to load or an unsupported
    CPU gives ``(False, reason)``.
    """
    with _lock:
        if "ok" not in _state:
            try:
                mod, device, flt = _open()
            except Exception as exc:  # anything the binding throws means "not usable here"
                _state.update(ok=False, reason=str(exc) or type(exc).__name__)
            else:
                _state.update(ok=True, reason="", module=mod, device=device, filter=flt)
        return bool(_state["ok"]), str(_state["reason"])


def warn_unavailable(reason: str) -> None:
    """Warn (once per distinct reason and process) that renders fall back to the raw estimate."""
    with _lock:
        seen = _state.setdefault("warned", set())
        if reason in seen:
            return
        seen.add(reason)
    warnings.warn(f"Open Image Denoise is unavailable ({reason}); rendering without denoising "
                  f"(the raw path-traced estimate, as with denoise='off')", DenoiserUnavailableWarning,
                  stacklevel=3)


def _contiguous(a: np.ndarray, name: str, shape) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.float32)
    if a.shape != shape:
        raise RenderError(f"denoise: {name} must have shape {shape}, got {a.shape}")
    return a


def denoise_oidn(color: np.ndarray, albedo: np.ndarray, normal: np.ndarray, settings: DenoiseSettings, *,
                 reference_radiance: float) -> np.ndarray:
    """Denoise an HDR colour image with its albedo and normal (OIDN ``RT`` filter, CPU).

    Parameters
    ----------
    color : numpy.ndarray
        float32 (H, W, 3) linear radiance, >= 0 (the raw estimate).
    albedo : numpy.ndarray
        float32 (H, W, 3) first-hit diffuse reflectance in [0, 1].
    normal : numpy.ndarray
        float32 (H, W, 3) first-hit shading normal (world space, [-1, 1]).
    settings : DenoiseSettings
        Quality, HDR scale, clean-aux flag and the pass-through level.
    reference_radiance : float
        The scene's reference radiance (white surface facing the sun), W m^-2 sr^-1;
        pixels above ``settings.passthrough`` times it keep their raw value.

    Returns
    -------
    numpy.ndarray
        float32 (H, W, 3), finite, >= 0.

    Raises
    ------
    RuntimeError
        OIDN is unavailable or failed (the caller falls back to the raw estimate).
    """
    ok, reason = oidn_status()
    if not ok:
        raise RuntimeError(reason)
    shape = np.shape(color)
    if len(shape) != 3 or shape[2] != 3:
        raise RenderError(f"denoise: color must be (H, W, 3), got {shape}")
    col = _contiguous(color, "color", shape)
    alb = np.clip(_contiguous(albedo, "albedo", shape), 0.0, 1.0)
    nrm = np.clip(_contiguous(normal, "normal", shape), -1.0, 1.0)
    limit = np.inf
    if settings.passthrough > 0:
        limit = float(settings.passthrough * reference_radiance)
    scale = 1.0 if settings.hdr_scale is None else float(settings.hdr_scale)
    limit = min(limit, 0.5 * _OIDN_HDR_MAX / scale)
    bright = np.any(col > limit, axis=-1)
    if bright.any():
        col = np.minimum(col, np.float32(limit))
    out = np.empty_like(col)
    with _lock:
        mod, device, flt = _state["module"], _state["device"], _state["filter"]
        fmt = mod.OIDN_FORMAT_FLOAT3
        flt.set_image("color", col, fmt)
        flt.set_image("albedo", alb, fmt)
        flt.set_image("normal", nrm, fmt)
        flt.set_image("output", out, fmt)
        flt.set_bool("hdr", True)
        flt.set_bool("cleanAux", bool(settings.clean_aux))
        flt.set_float("hdrScale", float("nan") if settings.hdr_scale is None else float(settings.hdr_scale))
        flt.set_int("quality", {"fast": mod.OIDN_QUALITY_FAST, "balanced": mod.OIDN_QUALITY_BALANCED,
                                "high": mod.OIDN_QUALITY_HIGH}[settings.quality])
        flt.commit()
        flt.execute()
        error = device.get_error()
        # the filter holds pointers to this call's arrays: unbind them before they go away
        for name in ("color", "albedo", "normal", "output"):
            flt.unset_image(name)
    if error:
        raise RuntimeError(f"OIDN failed: {error}")
    if not np.all(np.isfinite(out)):
        raise RuntimeError("OIDN returned non-finite values")
    np.maximum(out, 0.0, out=out)
    if bright.any():
        out[bright] = np.asarray(color, dtype=np.float32)[bright]
    return out


def with_name(settings: DenoiseSettings, name: str) -> DenoiseSettings:
    """A copy of ``settings`` with another denoiser name."""
    return replace(settings, name=name)
