"""Rendering a scene from a pose, with the on-disk cache.

Mitsuba is imported here only inside functions, after :mod:`scenes.variant`
has made sure the chosen variant can be loaded in this process.  Loaded
Mitsuba scenes are kept for the next render (a trajectory renders the same
scene from many poses), up to two at a time.
"""

from __future__ import annotations

import collections
import threading
import warnings

import numpy as np

from scenes.base import Scene, get_scene
from scenes.cache import cache_path, canonical_json, load_entry, render_key, resolve_cache_dir, store_entry
from scenes.camera import DEFAULT_FOV_DEG, _check_fov, _check_size, check_pose
from scenes.errors import RenderError
from scenes.variant import check_variant_name, choose_variant, ensure_variant

__all__ = ["render", "effective_spp", "MAX_SPP"]

#: Largest spp a single render accepts.
MAX_SPP = 1 << 16

_LOADED: "collections.OrderedDict[tuple[str, str], object]" = collections.OrderedDict()
_LOADED_MAX = 2
_lock = threading.RLock()


def effective_spp(spp: int) -> int:
    """Samples per pixel a render with ``spp`` actually takes (the sampler's stratification)."""
    from scenes._mitsuba import sampler_spp

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
                     fov_deg: float, variant: str) -> np.ndarray:
    import mitsuba as mi

    from scenes._mitsuba import sensor_dict

    with _lock:
        if mi.variant() != variant:
            mi.set_variant(variant)
        mi_scene = _loaded_scene(scene, variant)
        sensor = mi.load_dict(sensor_dict(pose, width=width, height=height, fov_deg=fov_deg, spp=spp))
        image = mi.render(mi_scene, sensor=sensor, spp=spp, seed=seed)
        return np.array(image, dtype=np.float32).reshape(height, width, -1)[..., :3].copy()


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
        Samples per pixel (see :func:`scenes.select_spp` for a noise target).
        The stratified sampler rounds it up to ``r * ceil(spp / r)``,
        ``r = isqrt(spp)`` (see :func:`effective_spp`; squares are kept).
    seed : int
        Sampler seed, 0 <= seed < 2**32: same inputs give the same bytes.
    fov_deg : float
        Horizontal field of view, degrees (see :func:`scenes.intrinsics`).
    cache_dir : None, str, pathlib.Path or False
        None: the default cache (``$EXPOSIM_CACHE`` or ``~/.cache/exposim/renders``);
        a path: that folder; False: no cache.
    variant : str, optional
        Mitsuba variant; default :func:`scenes.choose_variant` (``llvm_ad_rgb``
        when a child process proves it works, else ``scalar_rgb``).  An explicit
        (or ``EXPOSIM_MITSUBA_VARIANT``) variant is probed only when something
        must be rendered, so a cache hit costs only the file read.

    Returns
    -------
    numpy.ndarray
        float32 (height, width, 3) linear RGB radiance, W m^-2 sr^-1 (Rec.709
        primaries), finite and non-negative.

    Raises
    ------
    RenderError
        Bad size, spp, seed, field of view or pose; an unusable variant; a render
        with non-finite or negative values (never cached).
    SceneError
        Unknown scene name.
    """
    if isinstance(scene, str):
        scene = get_scene(scene)
    if not isinstance(scene, Scene):
        raise RenderError(f"scene must be a scenes.Scene or a scene name, got {type(scene).__name__}")
    _check_size(width, height)
    if width * height > 1 << 26:
        raise RenderError(f"image too large: {width}x{height}")
    spp = effective_spp(_check_int("spp", spp, 1, MAX_SPP))
    seed = _check_int("seed", seed, 0, 2**32 - 1)
    fov = _check_fov(fov_deg)
    m = check_pose(pose)
    # The variant only names the cache entry here; it is probed (for JIT variants, in a
    # child process) before this process loads it, i.e. on a cache miss.
    variant = check_variant_name(variant) if variant is not None else choose_variant()

    folder = resolve_cache_dir(cache_dir)
    path = None
    if folder is not None:
        key, material = render_key(scene, m, width=width, height=height, spp=spp, seed=seed, fov_deg=fov,
                                   variant=variant)
        path = cache_path(folder, key)
        if path.is_file():
            try:
                cached = load_entry(path)
            except RenderError:
                cached = None  # unreadable (e.g. truncated by a crash elsewhere): render again
            if cached is not None and cached.shape == (height, width, 3):
                return cached

    ensure_variant(variant)
    image = _render_uncached(scene, m, width=width, height=height, spp=spp, seed=seed, fov_deg=fov,
                             variant=variant)
    if not np.all(np.isfinite(image)):
        raise RenderError(f"render of {scene.name} produced non-finite values (variant {variant})")
    if image.min() < 0.0:
        raise RenderError(f"render of {scene.name} produced negative radiance (variant {variant})")
    if path is not None:
        try:
            store_entry(path, image, {"exposim_render_key": canonical_json(material)})
        except OSError as exc:  # a read-only or full cache must not lose a finished render
            warnings.warn(f"render cache: could not write {path}: {exc}", RuntimeWarning, stacklevel=2)
    return image
