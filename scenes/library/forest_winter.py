"""``forest_winter``: sunlit snow under a spruce stand: bright textured snow, dark trunks and crowns, crisp shadows."""

from __future__ import annotations

from scenes import textures as tx
from scenes.base import register_scene
from scenes.description import Material, SceneDescription
from scenes.errors import SceneError
from scenes.library.parts import (
    NEEDLE_ALBEDO,
    STREAM_DETAIL,
    STREAM_ROCKS,
    STREAM_TEXTURES,
    STREAM_TREES,
    bark_material,
    conifer_stand,
    ground_mesh,
    named_shapes,
    needle_material,
    require_param,
    rock_meshes,
    snow_material,
    stream_rng,
    sun_and_sky,
)

__all__ = ["forest_winter"]


# --------------------------------------------------------------------------------------------
# forest_winter
# --------------------------------------------------------------------------------------------

def _describe_forest_winter(seed: int, p: dict) -> SceneDescription:
    name = "forest_winter"
    sun, sky, ref = sun_and_sky(name, p)
    require_param(name, p, "tree_density_per_ha", 0.0, 3000.0)
    require_param(name, p, "trail_half_width_m", 0.5, 20.0)
    px = p["texture_px"]
    if px < 64 or px > 4096:
        raise SceneError(f"{name}: parameter texture_px must be in [64, 4096], got {px}")
    rt = stream_rng(seed, STREAM_TEXTURES)
    rd = stream_rng(seed, STREAM_DETAIL)
    materials = {
        "snow": snow_material(tx.snow_texture(rt, px), rd, p["detail_px"]),
        "bark": bark_material(tx.bark_texture(rt), rd),
        "needles": needle_material(tx.foliage_texture(rt, low=NEEDLE_ALBEDO[0], high=NEEDLE_ALBEDO[1]), rd),
        "rock": Material("diffuse", tx.rock_texture(rt)),
    }
    trunks, crowns, _ = conifer_stand(stream_rng(seed, STREAM_TREES), density_per_ha=p["tree_density_per_ha"],
                                      x_range=(-15.0, 90.0), y_range=(-35.0, 35.0),
                                      trail_half_width_m=p["trail_half_width_m"])
    rocks = rock_meshes(stream_rng(seed, STREAM_ROCKS), 12, (-5.0, 80.0), (-12.0, 12.0), p["trail_half_width_m"])
    shapes = named_shapes(snow=ground_mesh(300.0, 12.0), bark=trunks, needles=crowns, rock=rocks)
    return SceneDescription(materials=materials, shapes=tuple(shapes), sun=sun, sky=sky,
                            max_depth=p["max_depth"], reference_radiance=ref)


@register_scene(_describe_forest_winter)
def forest_winter(
    seed: int = 0,
    *,
    sun_elevation_deg: float = 28.0,
    sun_azimuth_deg: float = 40.0,
    sun_irradiance_w_m2: float = 1000.0,
    sun_cct_k: float = 5000.0,
    sky_cct_k: float = 12000.0,
    sky_fraction: float = 0.1,
    tree_density_per_ha: float = 450.0,
    trail_half_width_m: float = 1.5,
    texture_px: int = 1024,
    detail_px: int = 2048,
    max_depth: int = 3,
):
    """Sunlit snow under a spruce stand: bright textured snow, dark trunks and crowns, crisp shadows.

    The BorealHDR winter case (Montmorency forest, April): a trail through
    spruces, the sun in front-left so the camera sees backlit trunks and crown
    undersides against sunlit snow.

    Parameters
    ----------
    seed : int
        Tree placement, tree shapes and textures.
    sun_elevation_deg, sun_azimuth_deg : float
        Sun position, degrees (azimuth from +x towards +y).
    sun_irradiance_w_m2 : float
        Direct sun irradiance on a surface facing the sun, W m^-2.
    sun_cct_k, sky_cct_k : float
        Correlated colour temperatures of sun and sky, K (CIE daylight).
    sky_fraction : float
        Diffuse sky irradiance on an open horizontal surface over the direct
        normal sun irradiance (clear sky: 0.1-0.15).
    tree_density_per_ha : float
        Stems per hectare (boreal spruce stands: 300-2000).
    trail_half_width_m : float
        Half-width of the tree-free trail along +x, metres.
    texture_px : int
        Side of the snow texture (covers 12 m, repeated).
    detail_px : int
        Side of the snow's detail layer (litter, grain; covers 3 m, repeated).
    max_depth : int
        Path length limit of the path tracer.
    """
