"""``forest_summer``: sun patches and shade on a textured forest floor under a broadleaf canopy."""

from __future__ import annotations

import numpy as np

from scenes import textures as tx
from scenes.base import register_scene
from scenes.description import Material, SceneDescription
from scenes.errors import SceneError
from scenes.geometry import icosphere, merge, prisms, scatter_points
from scenes.library.parts import (
    STREAM_CANOPY,
    STREAM_ROCKS,
    STREAM_TEXTURES,
    STREAM_TREES,
    backdrop_mesh,
    ground_mesh,
    named_shapes,
    require_param,
    rock_meshes,
    stream_rng,
    sun_and_sky,
)

__all__ = ["forest_summer"]


# --------------------------------------------------------------------------------------------
# forest_summer
# --------------------------------------------------------------------------------------------

def _describe_forest_summer(seed: int, p: dict) -> SceneDescription:
    name = "forest_summer"
    sun, sky, ref = sun_and_sky(name, p)
    require_param(name, p, "canopy_density_per_ha", 0.0, 3000.0)
    require_param(name, p, "trail_half_width_m", 0.5, 20.0)
    px = p["texture_px"]
    if px < 64 or px > 4096:
        raise SceneError(f"{name}: parameter texture_px must be in [64, 4096], got {px}")
    rt = stream_rng(seed, STREAM_TEXTURES)
    materials = {
        "litter": Material("diffuse", tx.litter_texture(rt, px)),
        "bark": Material("diffuse", tx.bark_texture(rt, low=0.05, high=0.25)),
        "leaves": Material("diffuse", tx.foliage_texture(rt, low=0.04, high=0.16, colour=(0.5, 1.0, 0.35))),
        "shrub": Material("diffuse", tx.foliage_texture(rt, low=0.03, high=0.12, colour=(0.45, 1.0, 0.3))),
        "rock": Material("diffuse", tx.rock_texture(rt)),
    }
    rng = stream_rng(seed, STREAM_TREES)
    half = p["trail_half_width_m"]
    pts = scatter_points(rng, x_range=(-20.0, 105.0), y_range=(-35.0, 35.0),
                         density_per_m2=p["canopy_density_per_ha"] / 1e4, min_distance_m=3.0,
                         keep=lambda xy: np.abs(xy[:, 1]) > half + 0.5)
    trunk_rows, clumps, shrubs = [], [], []
    for x, y in pts:
        h = rng.uniform(14.0, 22.0)
        trunk_rows.append((x, y, rng.uniform(0.12, 0.3), 0.85 * h, rng.uniform(0, 2 * np.pi)))
        # a crown of leaf clumps between ~6 m and the top, spreading over the trail
        for _ in range(int(rng.integers(6, 11))):
            r = rng.uniform(1.2, 2.6)
            cz = rng.uniform(max(6.0, 0.45 * h), h - 0.5)
            spread = rng.uniform(0.0, 3.5)
            a = rng.uniform(0, 2 * np.pi)
            clumps.append(icosphere((x + spread * np.cos(a), y + spread * np.sin(a), cz), r, subdivisions=1,
                                    roughness=0.3, rng=rng, squash=0.7, texture_scale_m=1.0))
    rs = stream_rng(seed, STREAM_CANOPY)
    for x, y in scatter_points(rs, x_range=(-10.0, 85.0), y_range=(-15.0, 15.0), density_per_m2=0.02,
                               min_distance_m=1.5, keep=lambda xy: np.abs(xy[:, 1]) > half + 0.6):
        r = rs.uniform(0.3, 0.8)
        shrubs.append(icosphere((x, y, 0.6 * r), r, subdivisions=1, roughness=0.35, rng=rs, squash=0.8,
                                texture_scale_m=0.7))
    rocks = rock_meshes(stream_rng(seed, STREAM_ROCKS), 10, (-5.0, 80.0), (-10.0, 10.0), half)
    backdrop = backdrop_mesh((-25.0, 110.0), (-40.0, 40.0), 10.0)
    trunks = None
    if trunk_rows:
        t = np.array(trunk_rows)
        trunks = prisms(np.stack([t[:, 0], t[:, 1], np.full(len(t), -0.1)], -1), t[:, 2], t[:, 3], tapers=0.5,
                        phases=t[:, 4], texture_scale_m=1.0)
    shapes = named_shapes(litter=ground_mesh(300.0, 10.0), bark=trunks,
                          leaves=merge(clumps + [backdrop]), shrub=merge(shrubs) if shrubs else None,
                          rock=rocks)
    return SceneDescription(materials=materials, shapes=tuple(shapes), sun=sun, sky=sky,
                            max_depth=p["max_depth"], reference_radiance=ref)


@register_scene(_describe_forest_summer)
def forest_summer(
    seed: int = 0,
    *,
    sun_elevation_deg: float = 45.0,
    sun_azimuth_deg: float = 30.0,
    sun_irradiance_w_m2: float = 1000.0,
    sun_cct_k: float = 5500.0,
    sky_cct_k: float = 12000.0,
    sky_fraction: float = 0.12,
    canopy_density_per_ha: float = 260.0,
    trail_half_width_m: float = 1.2,
    texture_px: int = 1024,
    max_depth: int = 3,
):
    """Sun patches and shade on a textured forest floor under a broadleaf canopy.

    The BorealHDR summer case (Mont-Bélair, September): leaf clumps between 6 m
    and the tree tops leave gaps through which the sun draws bright patches on
    dark litter.

    Parameters
    ----------
    seed : int
        Placement, shapes and textures.
    sun_elevation_deg, sun_azimuth_deg, sun_irradiance_w_m2, sun_cct_k, sky_cct_k, sky_fraction
        Daylight, as in :func:`forest_winter`.
    canopy_density_per_ha : float
        Trees per hectare; their leaf clumps make the canopy.
    trail_half_width_m : float
        Half-width of the trunk-free trail along +x, metres.
    texture_px : int
        Side of the litter texture (covers 10 m, repeated).
    max_depth : int
        Path length limit of the path tracer.
    """
