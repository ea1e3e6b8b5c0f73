"""Rendering a scene from a pose, denoised by default, with the on-disk cache.

Mitsuba is imported here only inside functions, after :mod:`scenes.variant`
has made sure the chosen variant can be loaded in this process.  Loaded
Mitsuba scenes are kept for the next render (a trajectory renders the same
scene from many poses), up to two at a time.

The default path (``denoise="oidn"``, see :mod:`scenes.denoise`): the raw
path-traced estimate at ``spp`` (cached under its own key, so the raw image of
the same inputs is a cache hit afterwards), an albedo and normal pass of
Mitsuba's ``aov`` integrator, and Open Image Denoise; the denoised image is
cached under a key that holds the denoiser's name, version and settings.
"""

from __future__ import annotations

import collections
import threading
import time
import warnings

import numpy as np

from scenes.render_interrupts import render_array
from scenes.adaptive import AdaptiveSampling, as_adaptive, render_adaptive
from scenes.base import Scene, get_scene
from scenes.cache import KEY_ATTRIBUTE, cache_path, canonical_json, load_entry, render_key, resolve_cache_dir, \
    store_entry
from scenes.camera import DEFAULT_FOV_DEG, check_fov, check_size, check_pose
from scenes.denoise import DenoiseSettings, denoise_oidn, effective_denoise, resolve_denoise, warn_unavailable
from scenes.errors import RenderError
from scenes.variant import check_variant_name, choose_variant, ensure_variant

__all__ = ["render", "render_with_info", "render_depth", "effective_spp", "MAX_SPP"]

#: Largest spp a single render accepts.
MAX_SPP = 1 << 16

_LOADED: "collections.OrderedDict[tuple[str, str], object]" = collections.OrderedDict()
_LOADED_MAX = 2
_lock = threading.RLock()


def effective_spp(spp: int) -> int:
    """Samples per pixel a render with ``spp`` actually takes (the sampler's stratification)."""
    from scenes.mitsuba_objects import sampler_spp

    return sampler_spp(spp)


def _check_int(name: str, v, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= int(v) <= hi:
        raise RenderError(f"{name} must be an integer in [{lo}, {hi}], got {v!r}")
    return int(v)


def _loaded_scene(scene: Scene, variant: str):
    import mitsuba as mi

    key = (scene.cache_token(), variant)
    with _lock:
        if key in _LOADED:
            _LOADED.move_to_end(key)
            return _LOADED[key]
        mi_scene = mi.load_dict(scene.mitsuba_dict())
        _LOADED[key] = mi_scene
        while len(_LOADED) > _LOADED_MAX:
            _LOADED.popitem(last=False)
        return mi_scene


def _render_uncached(scene: Scene, pose: np.ndarray, *, width: int, height: int, spp: int, seed: int,
                     fov_deg: float, variant: str, adaptive: AdaptiveSampling | None = None) -> np.ndarray:
    import mitsuba as mi

    from scenes.mitsuba_objects import sensor_dict

    with _lock:
        if mi.variant() != variant:
            mi.set_variant(variant)
        mi_scene = _loaded_scene(scene, variant)

        def one(n: int, s: int, crop) -> np.ndarray:
            d = sensor_dict(pose, width=width, height=height, fov_deg=fov_deg, spp=n)
            x, y, w, h = (0, 0, width, height) if crop is None else crop
            if crop is not None:  # the film's crop window: only these pixels are sampled
                d["film"].update(crop_offset_x=x, crop_offset_y=y, crop_width=w, crop_height=h)
            image = render_array(mi, mi_scene, sensor=mi.load_dict(d), spp=n, seed=s)
            return image.reshape(h, w, -1)[..., :3].copy()

        if adaptive is None:
            return one(spp, seed, None)
        return render_adaptive(one, adaptive, width=width, height=height, spp=spp, seed=seed,
                               effective_spp=effective_spp, reference_radiance=scene.reference_radiance)[0]


def _render_aux_uncached(scene: Scene, pose: np.ndarray, *, width: int, height: int, spp: int, seed: int,
                         fov_deg: float, variant: str) -> tuple[np.ndarray, np.ndarray]:
    """(albedo, shading normal) of the first hit, float32 (H, W, 3) each, from Mitsuba's aov integrator."""
    import mitsuba as mi

    from scenes.mitsuba_objects import aov_integrator_dict, sensor_dict

    with _lock:
        if mi.variant() != variant:
            mi.set_variant(variant)
        mi_scene = _loaded_scene(scene, variant)
        sensor = mi.load_dict(sensor_dict(pose, width=width, height=height, fov_deg=fov_deg, spp=spp))
        integrator = mi.load_dict(aov_integrator_dict())
        a = render_array(mi, mi_scene, sensor=sensor, integrator=integrator, spp=spp, seed=seed)
        a = a.reshape(height, width, -1)
    if a.shape[2] != 6:  # pragma: no cover - the integrator's channel layout is fixed
        raise RenderError(f"aov pass returned {a.shape[2]} channels, expected 6 (albedo, normal)")
    return np.ascontiguousarray(a[..., :3]), np.ascontiguousarray(a[..., 3:])


def _read_cached(path, width: int, height: int, material: dict | None = None):
    if path is None or not path.is_file():
        return None
    try:
        cached = load_entry(path, material)  # key, checksum, finite and non-negative (scenes.cache)
    except RenderError:
        return None  # unreadable or bad (truncated, swapped, altered): render again and replace it
    return cached if cached.shape == (height, width, 3) else None


def _write_cached(path, image: np.ndarray, material: dict) -> None:
    if path is None:
        return
    try:
        store_entry(path, image, {KEY_ATTRIBUTE: canonical_json(material)})
    except OSError as exc:  # a read-only or full cache must not lose a finished render
        warnings.warn(f"render cache: could not write {path}: {exc}", RuntimeWarning, stacklevel=4)


def _check_image(image: np.ndarray, scene: Scene, variant: str, what: str) -> None:
    if not np.all(np.isfinite(image)):
        raise RenderError(f"{what} of {scene.name} produced non-finite values (variant {variant})")
    if image.min() < 0.0:
        raise RenderError(f"{what} of {scene.name} produced negative radiance (variant {variant})")


def render(
    scene: Scene | str,
    pose,
    *,
    width: int,
    height: int,
    spp: int,
    seed: int = 0,
    fov_deg: float = DEFAULT_FOV_DEG,
    cache_dir=None,
    variant: str | None = None,
    denoise: str | DenoiseSettings | None = None,
    adaptive: str | AdaptiveSampling | None = None,
) -> np.ndarray:
    """Render the HDR radiance a pinhole camera sees.

    Parameters
    ----------
    scene : Scene or str
        A scene (see :func:`scenes.get_scene`), or a scene name with default
        parameters and seed 0.
    pose : array-like
        4x4 camera-to-world pose, OpenCV camera frame (x right, y down, z
        forward), world z up, metres.
    width, height : int
        Image size in pixels.
    spp : int
        Samples per pixel of the path tracer (see :func:`scenes.select_spp` for a
        noise target).  The stratified sampler rounds it up to
        ``r * ceil(spp / r)``, ``r = isqrt(spp)`` (see :func:`effective_spp`;
        squares are kept).
    seed : int
        Sampler seed, 0 <= seed < 2**32: same inputs give the same bytes.
    fov_deg : float
        Horizontal field of view, degrees (see :func:`scenes.intrinsics`).
    cache_dir : None, str, pathlib.Path or False
        None: the default cache (``$EXPOSIM_CACHE`` or ``~/.cache/exposim/renders``);
        a path: that folder; False: no cache.
    variant : str, optional
        Mitsuba variant; default :func:`scenes.choose_variant` (``cuda_ad_rgb`` on an
        NVIDIA GPU, else ``llvm_ad_rgb``, each when a child process proves it works, else
        ``scalar_rgb``).  An explicit
        (or ``EXPOSIM_MITSUBA_VARIANT``) variant is probed only when something
        must be rendered, so a cache hit costs only the file read.
    denoise : str or scenes.denoise.DenoiseSettings, optional
        ``"oidn"``: denoise the estimate with Open Image Denoise, fed
        albedo and normal from Mitsuba's ``aov`` integrator (see
        :mod:`scenes.denoise`); ``"off"``: the raw path-traced estimate.  Default
        (None): ``"oidn"``, or ``$EXPOSIM_DENOISE`` when set
        (:func:`scenes.denoise.default_denoiser`).  When OIDN
        cannot run here, a :class:`scenes.denoise.DenoiserUnavailableWarning` says
        why and the raw estimate is returned.

    Returns
    -------
    numpy.ndarray
        float32 (height, width, 3) linear RGB radiance, W m^-2 sr^-1 (Rec.709
        primaries), finite and non-negative.

    Raises
    ------
    RenderError
        Bad size, spp, seed, field of view, pose or denoiser; an unusable variant; a
        render with non-finite or negative values (never cached).
    SceneError
        Unknown scene name.
    """
    image, _ = render_with_info(scene, pose, width=width, height=height, spp=spp, seed=seed, fov_deg=fov_deg,
                                cache_dir=cache_dir, variant=variant, denoise=denoise, adaptive=adaptive)
    return image


def render_with_info(
    scene: Scene | str,
    pose,
    *,
    width: int,
    height: int,
    spp: int,
    seed: int = 0,
    fov_deg: float = DEFAULT_FOV_DEG,
    cache_dir=None,
    variant: str | None = None,
    denoise: str | DenoiseSettings | None = None,
    adaptive: str | AdaptiveSampling | None = None,
) -> tuple[np.ndarray, dict]:
    """:func:`render`, also returning what happened.

    Returns
    -------
    image : numpy.ndarray
        As :func:`render`.
    info : dict
        ``denoise`` (the denoiser actually applied: ``"oidn"`` or ``"off"``),
        ``fallback`` (why OIDN was not applied when it was asked for, else None),
        ``cache_hit`` (the returned image was read from the cache), ``spp`` (the
        sampler's count), ``aux_spp`` (of the albedo/normal pass, 0 when none ran),
        and the wall-clock seconds of the parts that ran: ``render_s`` (path
        tracing, 0 on a raw cache hit), ``aux_s`` and ``denoise_s``.
    """
    if isinstance(scene, str):
        scene = get_scene(scene)
    if not isinstance(scene, Scene):
        raise RenderError(f"scene must be a scenes.Scene or a scene name, got {type(scene).__name__}")
    check_size(width, height)
    if width * height > 1 << 26:
        raise RenderError(f"image too large: {width}x{height}")
    spp = effective_spp(_check_int("spp", spp, 1, MAX_SPP))
    seed = _check_int("seed", seed, 0, 2**32 - 1)
    fov = check_fov(fov_deg)
    m = check_pose(pose)
    settings = resolve_denoise(denoise)  # bad names raise before anything else happens
    adaptive = as_adaptive(adaptive)
    # The variant only names the cache entry here; it is probed (for JIT variants, in a
    # child process) before this process loads it, i.e. on a cache miss.
    variant = check_variant_name(variant) if variant is not None else choose_variant()
    info = {"denoise": settings.name, "fallback": None, "cache_hit": False, "spp": spp, "aux_spp": 0,
            "render_s": 0.0, "aux_s": 0.0, "denoise_s": 0.0}
    settings, fallback = effective_denoise(settings)
    if fallback is not None:
        info.update(denoise="off", fallback=fallback)

    folder = resolve_cache_dir(cache_dir)
    common = dict(width=width, height=height, spp=spp, seed=seed, fov_deg=fov, variant=variant,
                  **({} if adaptive is None else {"adaptive": adaptive.key_material()}))

    def entry(material_denoise):
        if folder is None:
            return None, None
        key, material = render_key(scene, m, denoise=material_denoise, **common)
        return cache_path(folder, key), material

    final_path, final_material = entry(settings.key_material())
    cached = _read_cached(final_path, width, height, final_material)
    if cached is not None:
        info["cache_hit"] = True
        return cached, info

    raw_path, raw_material = (final_path, final_material) if not settings.enabled else entry(None)
    raw = _read_cached(raw_path, width, height, raw_material) if settings.enabled else None
    if raw is None:
        ensure_variant(variant)
        t0 = time.perf_counter()
        raw = _render_uncached(scene, m, width=width, height=height, spp=spp, seed=seed, fov_deg=fov,
                               variant=variant, **({} if adaptive is None else {"adaptive": adaptive}))
        info["render_s"] = time.perf_counter() - t0
        _check_image(raw, scene, variant, "render")
        _write_cached(raw_path, raw, raw_material)
    if not settings.enabled:
        return raw, info

    ensure_variant(variant)
    aux_spp = effective_spp(max(spp, settings.aux_spp))
    t0 = time.perf_counter()
    albedo, normal = _render_aux_uncached(scene, m, width=width, height=height, spp=aux_spp, seed=seed,
                                          fov_deg=fov, variant=variant)
    info["aux_s"] = time.perf_counter() - t0
    info["aux_spp"] = aux_spp
    t0 = time.perf_counter()
    try:
        image = denoise_oidn(raw, albedo, normal, settings, reference_radiance=scene.reference_radiance)
    except RuntimeError as exc:  # OIDN failed at run time: keep the raw estimate, say why
        warn_unavailable(str(exc))
        info.update(denoise="off", fallback=str(exc))
        return raw, info
    info["denoise_s"] = time.perf_counter() - t0
    _check_image(image, scene, variant, "denoised render")
    _write_cached(final_path, image, final_material)
    return image, info


def render_depth(scene: Scene | str, pose, *, width: int, height: int, fov_deg: float = DEFAULT_FOV_DEG,
                 spp: int = 4, seed: int = 0, variant: str | None = None) -> np.ndarray:
    """Distance from the camera centre to the first hit along each pixel's ray (uncached).

    Mitsuba's ``aov`` integrator (``depth``), averaged over ``spp`` samples per pixel (mixed
    at silhouettes).  Pixels that see no surface (sky) are 0.

    Returns
    -------
    numpy.ndarray
        float32 (height, width), metres.
    """
    import mitsuba as mi

    from scenes.mitsuba_objects import sensor_dict

    if isinstance(scene, str):
        scene = get_scene(scene)
    check_size(width, height)
    spp = effective_spp(_check_int("spp", spp, 1, MAX_SPP))
    seed = _check_int("seed", seed, 0, 2**32 - 1)
    fov = check_fov(fov_deg)
    m = check_pose(pose)
    variant = check_variant_name(variant) if variant is not None else choose_variant()
    ensure_variant(variant)
    with _lock:
        if mi.variant() != variant:
            mi.set_variant(variant)
        mi_scene = _loaded_scene(scene, variant)
        sensor = mi.load_dict(sensor_dict(m, width=width, height=height, fov_deg=fov, spp=spp))
        integrator = mi.load_dict({"type": "aov", "aovs": "dd:depth"})
        d = render_array(mi, mi_scene, sensor=sensor, integrator=integrator, spp=spp, seed=seed)
        d = d.reshape(height, width, -1)[..., 0].copy()
    return np.where(np.isfinite(d), d, 0.0).astype(np.float32)
