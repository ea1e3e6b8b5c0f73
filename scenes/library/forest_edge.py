"""``forest_edge``: walking out of dense spruce shade into open sunlit snow: the extreme-range case."""

from __future__ import annotations

import math

import numpy as np

from scenes import textures as tx
from scenes.base import register_scene
from scenes.description import Material, SceneDescription, Shape
from scenes.errors import SceneError
from scenes.geometry import merge, prisms, quad, scatter_points
from scenes.lighting import daylight_rgb
from scenes.library.parts import (
    STREAM_CANOPY,
    STREAM_TEXTURES,
    STREAM_TREES,
    conifer_stand,
    ground_mesh,
    named_shapes,
    require_param,
    stream_rng,
    sun_and_sky,
)

__all__ = ["forest_edge"]


# --------------------------------------------------------------------------------------------
# forest_edge
# --------------------------------------------------------------------------------------------

def _describe_forest_edge(seed: int, p: dict) -> SceneDescription:
    name = "forest_edge"
    sun, sky, ref = sun_and_sky(name, p)
    require_param(name, p, "exit_x_m", 1.0, 500.0)
    require_param(name, p, "tunnel_length_m", 5.0, 500.0)
    require_param(name, p, "roof_gap_fraction", 0.0, 0.5)
    require_param(name, p, "tunnel_half_width_m", 1.0, 20.0)
    require_param(name, p, "canopy_height_m", 2.5, 30.0)
    require_param(name, p, "canopy_transmittance", 0.0, 0.2)
    px = p["texture_px"]
    if px < 64 or px > 4096:
        raise SceneError(f"{name}: parameter texture_px must be in [64, 4096], got {px}")
    rt = stream_rng(seed, STREAM_TEXTURES)
    materials = {
        "snow": Material("diffuse", tx.snow_texture(rt, px)),
        "litter": Material("diffuse", tx.albedo_map(tx.fractal_noise((px // 2, px // 2), rt, beta=1.3),
                                                    0.02, 0.12, (1.0, 0.8, 0.55))),
        "bark": Material("diffuse", tx.bark_texture(rt, low=0.02, high=0.1)),
        "needles": Material("diffuse", tx.foliage_texture(rt)),
    }
    ex, length, w, h = p["exit_x_m"], p["tunnel_length_m"], p["tunnel_half_width_m"], p["canopy_height_m"]
    x_back = ex - length
    # floor: needle litter inside the stand, snow outside
    litter = ground_mesh(60.0, 6.0, x0=x_back - 5.0, x1=ex)
    snow = ground_mesh(300.0, 12.0, x0=ex, x1=ex + 300.0)
    # dense canopy: side walls, back wall, the forest edge face around the opening
    foliage = [
        quad((x_back, -w, 0.0), (length, 0.0, 0.0), (0.0, 0.0, h), texture_scale_m=1.5),  # right wall (y = -w)
        quad((x_back, w, 0.0), (length, 0.0, 0.0), (0.0, 0.0, h), texture_scale_m=1.5),  # left wall
        quad((x_back, -w - 1.0, 0.0), (0.0, 2 * w + 2.0, 0.0), (0.0, 0.0, h), texture_scale_m=1.5),  # back
        quad((ex, -60.0, 0.0), (0.0, 60.0 - w, 0.0), (0.0, 0.0, 2.5 * h), texture_scale_m=1.5),  # edge face
        quad((ex, w, 0.0), (0.0, 60.0 - w, 0.0), (0.0, 0.0, 2.5 * h), texture_scale_m=1.5),
        quad((ex, -w, h), (0.0, 2 * w, 0.0), (0.0, 0.0, 1.5 * h), texture_scale_m=1.5),  # above the opening
    ]
    # roof of 1 m cells, a few left open (sun flecks); the closed ones glow faintly downwards with
    # the daylight the dense canopy lets through (transmittance x open-sky irradiance, diffused)
    rr = stream_rng(seed, STREAM_CANOPY)
    cell = 1.0
    nx, ny = int(math.ceil(length / cell)), int(math.ceil((2 * w + 2.0) / cell))
    open_cells = rr.random((nx, ny)) < p["roof_gap_fraction"]
    roof = []
    for i in range(nx):
        for j in range(ny):
            if not open_cells[i, j]:
                # edges chosen so the face normal points down (-z): the emitting side
                roof.append(quad((x_back + i * cell, -w - 1.0 + j * cell, h), (0.0, cell, 0.0), (cell, 0.0, 0.0),
                                 texture_scale_m=1.5))
    open_sky = p["sun_irradiance_w_m2"] * (math.sin(math.radians(p["sun_elevation_deg"])) + p["sky_fraction"])
    leak = p["canopy_transmittance"] * open_sky / math.pi
    leak_rgb = tuple(float(v) * leak for v in daylight_rgb(p["sun_cct_k"]))
    # trunks lining the tunnel, and a distant tree line beyond the snowfield
    rt2 = stream_rng(seed, STREAM_TREES)
    trunks = []
    for side in (-1.0, 1.0):
        xy = scatter_points(rt2, x_range=(x_back + 1.0, ex - 0.5), y_range=(1.4, w - 0.3), density_per_m2=0.25,
                            min_distance_m=0.9)
        if len(xy):
            trunks.append(prisms(np.stack([xy[:, 0], side * xy[:, 1], np.full(len(xy), -0.1)], -1),
                                 rt2.uniform(0.08, 0.22, len(xy)), h + 0.2, tapers=0.8,
                                 phases=rt2.uniform(0, 2 * np.pi, len(xy)), texture_scale_m=1.0))
    far_trunks, far_crowns, _ = conifer_stand(rt2, density_per_ha=300.0, x_range=(ex + 60.0, ex + 110.0),
                                              y_range=(-80.0, 80.0), trail_half_width_m=0.0,
                                              keep=lambda xy: np.ones(len(xy), bool))
    shapes = named_shapes(litter=litter, snow=snow, needles=merge(foliage + ([far_crowns] if far_crowns else [])),
                          bark=merge(trunks + ([far_trunks] if far_trunks else [])))
    if roof:
        shapes.append(Shape("mesh", material="needles", mesh=merge(roof), radiance=leak_rgb if leak > 0 else None))
    return SceneDescription(materials=materials, shapes=tuple(shapes), sun=sun, sky=sky,
                            max_depth=p["max_depth"], reference_radiance=ref,
                            notes={"exit_x_m": ex, "canopy_radiance": leak})


@register_scene(_describe_forest_edge, start=(0.0, 0.0))
def forest_edge(
    seed: int = 0,
    *,
    sun_elevation_deg: float = 35.0,
    sun_azimuth_deg: float = 90.0,
    sun_irradiance_w_m2: float = 1000.0,
    sun_cct_k: float = 5200.0,
    sky_cct_k: float = 12000.0,
    sky_fraction: float = 0.1,
    exit_x_m: float = 30.0,
    tunnel_length_m: float = 50.0,
    tunnel_half_width_m: float = 3.0,
    canopy_height_m: float = 4.5,
    roof_gap_fraction: float = 0.003,
    canopy_transmittance: float = 5e-4,
    texture_px: int = 1024,
    max_depth: int = 3,
):
    """Walking out of dense spruce shade into open sunlit snow: the extreme-range case.

    A trail runs through a closed stand (walls and a roof of needles, trunks
    along both sides) and exits at ``exit_x_m`` onto a sunlit snowfield bounded
    by a distant tree line.  Inside, no sky is visible: the light comes from the
    opening, a few sun flecks through roof gaps, and the faint daylight the
    canopy transmits (modelled as a dim downward emission of the roof,
    ``canopy_transmittance`` times the open-sky irradiance, diffused).  The
    default walk (0.56 m/s from x = 0) reaches the edge after about 54 s; the
    sun comes from the side, so it lights the snow beyond the edge but does not
    shine into the opening.

    Parameters
    ----------
    seed : int
        Trunks, roof gaps and textures.
    sun_elevation_deg, sun_azimuth_deg, sun_irradiance_w_m2, sun_cct_k, sky_cct_k, sky_fraction
        Daylight, as in :func:`forest_winter`.
    exit_x_m : float
        x of the forest edge, metres.
    tunnel_length_m : float
        Length of the covered trail, ending at the edge, metres.
    tunnel_half_width_m, canopy_height_m : float
        Half-width and height of the covered trail, metres.
    roof_gap_fraction : float
        Fraction of 1 m roof cells left open (sun flecks).
    canopy_transmittance : float
        Fraction of the open-sky irradiance the closed canopy passes (dense
        spruce: well below 1 %; 0 makes the roof opaque).
    texture_px, max_depth : int
        As in :func:`forest_winter`.
    """
