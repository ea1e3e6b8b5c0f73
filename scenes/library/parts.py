"""Parts the procedural scenes share: random streams, materials with their detail textures, sunlight and sky,
ground, conifer stands, rocks, backdrops."""

from __future__ import annotations

import math

import numpy as np

from scenes import textures as tx
from scenes.description import Material, Shape, Sun
from scenes.errors import SceneError
from scenes.geometry import MeshData, icosphere, merge, prisms, quad, scatter_points
from scenes.geometry import whorls as branch_whorls
from scenes.lighting import SUN_ANGULAR_DIAMETER_DEG, daylight_rgb, sky_envmap, sun_direction

__all__ = [
    "SNOW_DETAIL", "SNOW_DETAIL_RANGE", "SNOW_RELIEF", "BARK_DETAIL_RANGE", "NEEDLE_DETAIL", "NEEDLE_DETAIL_RANGE",
    "NEEDLE_ALBEDO", "STREAM_TEXTURES", "STREAM_TREES", "STREAM_ROCKS", "STREAM_CANOPY", "STREAM_DETAIL",
    "stream_rng", "require_param", "sun_and_sky", "snow_material", "bark_material", "needle_material", "ground_mesh",
    "conifer_stand", "rock_meshes", "backdrop_mesh", "named_shapes",
]

# Purposes of the independent random streams of a scene: changing the tree
# density must not change the snow texture, and so on.
STREAM_TEXTURES, STREAM_TREES, STREAM_ROCKS, STREAM_CANOPY, STREAM_DETAIL = 1, 2, 3, 4, 5

#: Ground textures cover this many metres per repeat; their detail layers 3 m.
_GROUND_TILE_M, _DETAIL_TILE_M = 12.0, 3.0


#: Texture settings of forest_winter's detail layers (see :mod:`scenes.textures`), chosen so
#: that denoised 8 ms frames match the real BorealHDR frames' SIFT keypoint density and median
#: gradient (``python -m validation.render_study``).
SNOW_DETAIL = {"grain_contrast": 0.8, "grain_beta": 1.6, "grain_min_mm": 12.0, "needles_per_m2": 6000.0,
               "twigs_per_m2": 120.0, "debris_per_m2": 2000.0, "blobs_per_m2": 600.0}
SNOW_DETAIL_RANGE = (0.1, 1.05)
SNOW_RELIEF = {"beta": 3.0, "size": 512, "amplitude_m": 0.03}
BARK_DETAIL_RANGE = (0.3, 1.4)
NEEDLE_DETAIL = {"clump_cm": 3.0, "gap_fraction": 0.45}
NEEDLE_DETAIL_RANGE = (0.03, 4.0)
#: Luminance albedo range of the spruce foliage (before the needle-clump detail).
NEEDLE_ALBEDO = (0.03, 0.13)

def snow_material(albedo: np.ndarray, rng: np.random.Generator, detail_px: int) -> Material:
    """Snow: metre-scale albedo, centimetre-scale litter and grain, bump-mapped crust."""
    if detail_px < 64 or detail_px > 4096:
        raise SceneError(f"detail_px must be in [64, 4096], got {detail_px}")
    relief = tx.relief(rng, int(SNOW_RELIEF["size"]), beta=float(SNOW_RELIEF["beta"]))
    return Material("diffuse", albedo, detail=tx.snow_detail(rng, detail_px, tile_m=_DETAIL_TILE_M, **SNOW_DETAIL),
                    detail_repeat=_GROUND_TILE_M / _DETAIL_TILE_M, detail_range=SNOW_DETAIL_RANGE,
                    bump=relief, bump_repeat=_GROUND_TILE_M / _DETAIL_TILE_M,
                    bump_amplitude=float(SNOW_RELIEF["amplitude_m"]))


def bark_material(albedo: np.ndarray, rng: np.random.Generator) -> Material:
    """Bark (1 m texture repeats): plates and cracks."""
    return Material("diffuse", albedo, detail=tx.bark_detail(rng), detail_repeat=2.0, detail_range=BARK_DETAIL_RANGE)


def needle_material(albedo: np.ndarray, rng: np.random.Generator) -> Material:
    """Spruce foliage (1 m texture repeats): needle clumps over 2 m tiles, dark gaps."""
    return Material("diffuse", albedo, detail=tx.needle_clumps(rng, 512, tile_m=2.0, **NEEDLE_DETAIL),
                    detail_repeat=0.5, detail_range=NEEDLE_DETAIL_RANGE)


def stream_rng(seed: int, purpose: int) -> np.random.Generator:
    """The scene's independent random stream for one purpose (a ``STREAM_*`` constant)."""
    return np.random.default_rng([int(seed), purpose])


def require_param(scene: str, p: dict, key: str, lo: float, hi: float) -> float:
    """``p[key]``, or a :class:`SceneError` naming the scene and parameter when it is outside [lo, hi]."""
    v = p[key]
    if not lo <= v <= hi:
        raise SceneError(f"{scene}: parameter {key} must be in [{lo}, {hi}], got {v!r}")
    return v


def sun_and_sky(scene: str, p: dict, *, disk_visible: bool = False) -> tuple[Sun, np.ndarray, float]:
    require_param(scene, p, "sun_elevation_deg", 0.5, 90.0)
    require_param(scene, p, "sun_irradiance_w_m2", 1e-3, 1e5)
    require_param(scene, p, "sky_fraction", 0.0, 1.0)
    require_param(scene, p, "sun_cct_k", 4000.0, 25000.0)
    require_param(scene, p, "sky_cct_k", 4000.0, 25000.0)
    direction = sun_direction(p["sun_elevation_deg"], p["sun_azimuth_deg"])
    sun = Sun(
        direction=direction,
        irradiance_rgb=daylight_rgb(p["sun_cct_k"]) * p["sun_irradiance_w_m2"],
        disk_visible=disk_visible,
        angular_diameter_deg=SUN_ANGULAR_DIAMETER_DEG,
    )
    sky = sky_envmap(
        horizontal_irradiance=p["sky_fraction"] * p["sun_irradiance_w_m2"],
        sky_rgb=daylight_rgb(p["sky_cct_k"]),
        sun_dir=direction,
    )
    return sun, sky, p["sun_irradiance_w_m2"] / math.pi


def ground_mesh(half_size_m: float, texture_scale_m: float, x0: float = 0.0, x1: float | None = None) -> MeshData:
    """Horizontal ground quad (normal +z) over x in [x0 - half, x1 or x0 + half], |y| <= half."""
    xa = x0 - half_size_m if x1 is None else x0
    xb = x0 + half_size_m if x1 is None else x1
    return quad((xa, -half_size_m, 0.0), (xb - xa, 0.0, 0.0), (0.0, 2 * half_size_m, 0.0),
                texture_scale_m=texture_scale_m)


def conifer_stand(rng: np.random.Generator, *, density_per_ha: float, x_range: tuple, y_range: tuple,
                  trail_half_width_m: float, height_range: tuple = (8.0, 17.0), whorls: int = 5, keep=None
                   ) -> tuple[MeshData | None, MeshData | None, np.ndarray]:
    """Spruces scattered around a trail along the x axis; crowns never reach into the trail.

    A spruce is a tapered trunk and a crown of ``whorls`` stacked branch whorls
    (open cones with a star-shaped rim of branch tips, wide at the bottom,
    narrowing to the top, overlapping like branch tiers; see
    :func:`scenes.geometry.whorls`).
    Returns (trunks mesh, crowns mesh, trunk positions).
    """
    def default_keep(xy):
        return np.abs(xy[:, 1]) > trail_half_width_m + 0.4

    pts = scatter_points(rng, x_range=x_range, y_range=y_range, density_per_m2=density_per_ha / 1e4,
                         min_distance_m=1.2, keep=keep or default_keep)
    n = pts.shape[0]
    if n == 0:
        return None, None, pts
    height = rng.uniform(*height_range, n)
    clearance = np.maximum(0.6, np.abs(pts[:, 1]) - trail_half_width_m - 0.2)  # crown edge outside the trail
    crown_r = np.clip(0.2 * height * rng.uniform(0.8, 1.15, n), 0.6, clearance)
    crown_base = rng.uniform(0.4, 2.2, n)
    trunk_r = rng.uniform(0.07, 0.2, n)
    trunks = prisms(np.stack([pts[:, 0], pts[:, 1], np.full(n, -0.1)], -1), trunk_r, 0.8 * height, tapers=0.35,
                    phases=rng.uniform(0, 2 * np.pi, n), segments=10, texture_scale_m=1.0)
    frac = np.arange(whorls)[None, :] / whorls  # (1, whorls)
    span = (height - crown_base)[:, None]
    base_z = crown_base[:, None] + frac * span * 0.92
    radius = crown_r[:, None] * (1.0 - frac) * rng.uniform(0.85, 1.1, (n, whorls)) + 0.15
    top_z = np.minimum(height[:, None], base_z + 1.9 * span / whorls)
    top_z[:, -1] = height
    centers = np.stack([np.repeat(pts[:, 0], whorls), np.repeat(pts[:, 1], whorls), base_z.ravel()], -1)
    crowns = branch_whorls(centers, radius.ravel(), (top_z - base_z).ravel(), rng=rng, texture_scale_m=1.0)
    return trunks, crowns, pts


def rock_meshes(rng: np.random.Generator, count: int, x_range: tuple, y_range: tuple, trail_half_width_m: float,
                size_range: tuple = (0.3, 1.0)) -> MeshData | None:
    meshes = []
    for _ in range(count):
        x = rng.uniform(*x_range)
        y = rng.choice([-1.0, 1.0]) * rng.uniform(trail_half_width_m + 0.5, max(y_range) + 1e-9)
        r = rng.uniform(*size_range)
        meshes.append(icosphere((x, y, 0.1 * r), r, subdivisions=2, roughness=0.25, rng=rng, squash=0.6,
                                texture_scale_m=1.5))
    return merge(meshes) if meshes else None


def backdrop_mesh(x_range: tuple, y_range: tuple, height_m: float) -> MeshData:
    """Four inward-facing walls of foliage closing the horizon around a stand (the forest goes on)."""
    (x0, x1), (y0, y1) = x_range, y_range
    return merge([
        quad((x1, y0, 0.0), (0.0, y1 - y0, 0.0), (0.0, 0.0, height_m), texture_scale_m=3.0),
        quad((x0, y1, 0.0), (0.0, y0 - y1, 0.0), (0.0, 0.0, height_m), texture_scale_m=3.0),
        quad((x0, y0, 0.0), (x1 - x0, 0.0, 0.0), (0.0, 0.0, height_m), texture_scale_m=3.0),
        quad((x1, y1, 0.0), (x0 - x1, 0.0, 0.0), (0.0, 0.0, height_m), texture_scale_m=3.0),
    ])


def named_shapes(**named) -> list[Shape]:
    """One mesh shape per ``material=mesh`` keyword, skipping meshes that are None."""
    return [Shape("mesh", material=mat, mesh=mesh) for mat, mesh in named.items() if mesh is not None]
