"""On-disk render cache: OpenEXR float32 RGB files (:mod:`emulator.io.exr`) named by a content hash.

The key hashes everything that affects the pixels: the scene (name, every
parameter, seed, and a fingerprint of the scene-building source code), the
pose, the image size, the field of view, spp, the sampler seed, the Mitsuba
variant, the Mitsuba and Dr.Jit versions, and the denoiser (its name, the
version of the library and binding, and every setting; ``{"name": "off"}`` for
the raw estimate).  A hit is read back exactly (EXR
float32 with lossless ZIP compression) and costs only the read.  Files are
written to a temporary name and moved into place with :func:`os.replace`, so a
reader never sees a partial file.  The EXR bytes are deterministic: the same
render writes the same file.

Every entry carries, as EXR header attributes, its key material (``exposim_render_key``)
and the SHA-256 of its pixels (``exposim_pixels_sha256``); :func:`load_entry` given the
material checks both, and that the radiance is finite and non-negative, as a fresh render
is checked (an entry written before checksums has its key and values checked).  A bad entry
(another key's file, altered pixels, NaN or negative values) raises :class:`CacheEntryError`, and :func:`scenes.render.render`
renders again and replaces it.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from importlib import metadata
from pathlib import Path

import numpy as np

from scenes.errors import RenderError

__all__ = ["ENV_CACHE_DIR", "default_cache_dir", "resolve_cache_dir", "canonical_json", "library_versions",
           "render_key", "cache_path", "store_entry", "load_entry", "CacheEntryError", "pixels_sha256",
           "KEY_ATTRIBUTE", "SHA_ATTRIBUTE"]

#: EXR header attributes of an entry: its key material (canonical JSON) and its pixels' SHA-256.
KEY_ATTRIBUTE = "exposim_render_key"
SHA_ATTRIBUTE = "exposim_pixels_sha256"


class CacheEntryError(RenderError):
    """A render-cache entry that must not be used (wrong key, bad checksum, NaN or negative)."""


def pixels_sha256(radiance: np.ndarray) -> str:
    """SHA-256 of the float32 pixel bytes (C order)."""
    return hashlib.sha256(np.ascontiguousarray(radiance, dtype=np.float32).tobytes()).hexdigest()

#: Environment variable overriding the default cache folder.
ENV_CACHE_DIR = "EXPOSIM_CACHE"

#: Bump when the key layout changes (2: the denoiser joined the key).
KEY_VERSION = 2


def default_cache_dir() -> Path:
    """``$EXPOSIM_CACHE`` if set, else ``~/.cache/exposim/renders``."""
    env = os.environ.get(ENV_CACHE_DIR, "").strip()
    return Path(env).expanduser() if env else Path.home() / ".cache" / "exposim" / "renders"


def resolve_cache_dir(cache_dir) -> Path | None:
    """None -> the default folder; False -> no caching (returns None); else the given path."""
    if cache_dir is False:
        return None
    if cache_dir is None:
        return default_cache_dir()
    return Path(cache_dir).expanduser()


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, float) and obj == 0.0:
        return 0.0  # -0.0 and 0.0 hash alike
    return obj


def canonical_json(obj) -> str:
    """Deterministic JSON (sorted keys, no spaces, floats as shortest round-trip repr)."""
    return json.dumps(_jsonable(obj), sort_keys=True, separators=(",", ":"), allow_nan=False)


@functools.lru_cache(maxsize=1)
def library_versions() -> dict:
    """Installed Mitsuba and Dr.Jit versions (from package metadata: no import)."""
    out = {}
    for pkg in ("mitsuba", "drjit"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = "missing"
    return out


def render_key(scene, pose, *, width: int, height: int, spp: int, seed: int, fov_deg: float,
               variant: str, denoise: dict | None = None, adaptive: dict | None = None) -> tuple[str, dict]:
    """(hex SHA-256 key, the JSON-ready material it hashes) of one render.

    ``denoise`` is :meth:`scenes.denoise.DenoiseSettings.key_material` (None: the raw
    estimate, ``{"name": "off"}``).  ``adaptive`` is :meth:`scenes.adaptive.AdaptiveSampling.key_material`;
    it joins the material only when given, so every other render keeps its key.
    """
    material = {
        "v": KEY_VERSION,
        "scene": scene.key_material(),
        "pose": np.asarray(pose, dtype=np.float64).round(12).tolist(),
        "width": int(width),
        "height": int(height),
        "spp": int(spp),
        "seed": int(seed),
        "fov_deg": round(float(fov_deg), 12),
        "variant": str(variant),
        "versions": library_versions(),
        "denoise": {"name": "off"} if denoise is None else dict(denoise),
    }
    if adaptive is not None:
        material["adaptive"] = dict(adaptive)
    return hashlib.sha256(canonical_json(material).encode()).hexdigest(), material


def cache_path(cache_dir: Path, key: str) -> Path:
    """Where a key lives: ``cache_dir/<first two hex>/<key>.exr``."""
    return Path(cache_dir) / key[:2] / f"{key}.exr"


def store_entry(path, radiance: np.ndarray, attributes: dict | None = None) -> Path:
    """Write one cache entry: float32 RGB radiance as OpenEXR (:mod:`emulator.io.exr`), replacing ``path``.

    Parameters
    ----------
    path : str or pathlib.Path
        Destination; its folder is created.
    radiance : numpy.ndarray
        float32 (H, W, 3).
    attributes : dict, optional
        Extra string header attributes (e.g. the cache key material).
    """
    from emulator.io.exr import write_exr

    a = np.ascontiguousarray(radiance)
    if a.dtype != np.float32 or a.ndim != 3 or a.shape[2] != 3:
        raise RenderError(f"{path}: a cache entry must be float32 (H, W, 3) radiance, got {a.dtype} {a.shape}")
    return write_exr(path, a, overwrite=True, attributes={**(attributes or {}), SHA_ATTRIBUTE: pixels_sha256(a)})


def load_entry(path, material: dict | None = None) -> np.ndarray:
    """Read one cache entry as float32 (H, W, 3).

    With ``material`` (what :func:`render_key` hashed), the entry must hold that key material
    and the checksum of its pixels, and its radiance must be finite and non-negative.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    CacheEntryError
        The entry is another key's, fails its checksum, or holds NaN or negative radiance.
    RenderError
        The file is not a readable RGB EXR.
    """
    from emulator.errors import DatasetError
    from emulator.io.exr import read_exr

    try:
        a = read_exr(path)
    except DatasetError as exc:
        raise RenderError(str(exc)) from exc
    if a.ndim != 3:
        raise RenderError(f"{path}: not an RGB OpenEXR file (one channel)")
    if material is not None:
        from emulator.io.exr import read_exr_attributes

        try:
            header = read_exr_attributes(path)
        except DatasetError as exc:
            raise RenderError(str(exc)) from exc
        if header.get(KEY_ATTRIBUTE) != canonical_json(material):
            raise CacheEntryError(f"{path}: render cache entry of another render (key material differs)")
        sha = header.get(SHA_ATTRIBUTE)  # absent in entries written before checksums: key and values still checked
        if sha is not None and sha != pixels_sha256(a):
            raise CacheEntryError(f"{path}: render cache entry fails its pixel checksum")
        if not np.all(np.isfinite(a)) or a.min() < 0.0:
            raise CacheEntryError(f"{path}: render cache entry holds non-finite or negative radiance")
    return a
