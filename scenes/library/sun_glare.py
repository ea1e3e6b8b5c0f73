"""``sun_glare``: a low sun in view through sparse spruces, and its glint on a frozen pond ahead."""

from __future__ import annotations

import numpy as np

from scenes import textures as tx
from scenes.base import register_scene
from scenes.description import Material, SceneDescription
from scenes.errors import SceneError
from scenes.geometry import quad
from scenes.library.parts import (
    STREAM_TEXTURES,
    STREAM_TREES,
    conifer_stand,
    ground_mesh,
    named_shapes,
    require_param,
    stream_rng,
    sun_and_sky,
)

__all__ = ["sun_glare"]


# --------------------------------------------------------------------------------------------
# sun_glare
# --------------------------------------------------------------------------------------------

def _describe_sun_glare(seed: int, p: dict) -> SceneDescription:
    name = "sun_glare"
    sun, sky, ref = sun_and_sky(name, p, disk_visible=True)
    require_param(name, p, "tree_density_per_ha", 0.0, 3000.0)
    require_param(name, p, "ice_roughness", 0.005, 1.0)
    px = p["texture_px"]
    if px < 64 or px > 4096:
        raise SceneError(f"{name}: parameter texture_px must be in [64, 4096], got {px}")
    rt = stream_rng(seed, STREAM_TEXTURES)
    ice_noise = tx.fractal_noise((256, 256), rt, beta=2.0)
    materials = {
        "snow": Material("diffuse", tx.snow_texture(rt, px)),
        "bark": Material("diffuse", tx.bark_texture(rt)),
        "needles": Material("diffuse", tx.foliage_texture(rt)),
        "ice": Material("roughplastic", tx.albedo_map(ice_noise, 0.04, 0.2, (0.85, 0.95, 1.0)),
                        roughness=p["ice_roughness"], ior=1.31),
    }
    trunks, crowns, _ = conifer_stand(stream_rng(seed, STREAM_TREES), density_per_ha=p["tree_density_per_ha"],
                                      x_range=(-15.0, 120.0), y_range=(-35.0, 35.0), trail_half_width_m=1.5,
                                      keep=lambda xy: (np.abs(xy[:, 1]) > 1.9)
                                      & ~((xy[:, 0] > p["ice_start_m"] - 2) & (xy[:, 0] < p["ice_start_m"] + 27)
                                           & (np.abs(xy[:, 1]) < 10)))
    x0 = p["ice_start_m"]
    pond = quad((x0, -7.0, 0.005), (25.0, 0.0, 0.0), (0.0, 14.0, 0.0), texture_scale_m=6.0)
    shapes = named_shapes(snow=ground_mesh(300.0, 12.0), bark=trunks, needles=crowns, ice=pond)
    return SceneDescription(materials=materials, shapes=tuple(shapes), sun=sun, sky=sky,
                            max_depth=p["max_depth"], reference_radiance=ref)


@register_scene(_describe_sun_glare)
def sun_glare(
    seed: int = 0,
    *,
    sun_elevation_deg: float = 9.0,
    sun_azimuth_deg: float = 6.0,
    sun_irradiance_w_m2: float = 800.0,
    sun_cct_k: float = 4200.0,
    sky_cct_k: float = 10000.0,
    sky_fraction: float = 0.12,
    tree_density_per_ha: float = 150.0,
    ice_start_m: float = 8.0,
    ice_roughness: float = 0.06,
    texture_px: int = 1024,
    max_depth: int = 3,
):
    """A low sun in view through sparse spruces, and its glint on a frozen pond ahead.

    The sun is modelled as a distant sphere of the sun's angular diameter
    (0.533 deg) carrying the same irradiance as a directional sun would, so the
    disk itself (about 1.5e7 W m^-2 sr^-1 at 800 W m^-2) appears in the frame; the
    rough ice reflects it as a bright specular glint below the horizon.

    Parameters
    ----------
    seed : int
        Placement, shapes and textures.
    sun_elevation_deg, sun_azimuth_deg, sun_irradiance_w_m2, sun_cct_k, sky_cct_k, sky_fraction
        Daylight, as in :func:`forest_winter`; the defaults put the sun ahead of
        the default walk, inside the vertical field of view.
    tree_density_per_ha : float
        Stems per hectare (sparse, so the sun shows between trunks).
    ice_start_m : float
        x where the frozen pond (25 m long, 14 m wide, on the trail) starts.
    ice_roughness : float
        GGX alpha of the ice surface (smaller: a smaller, brighter glint).
    texture_px, max_depth : int
        As in :func:`forest_winter`.
    """
