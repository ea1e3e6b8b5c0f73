"""The procedural scenes.

Each public function here is a scene builder registered in
:data:`scenes.SCENES`: its keyword-only parameters are the scene's named
parameters.  The matching ``_describe_*`` function builds the geometry,
textures and lighting as a :class:`~scenes.description.SceneDescription`.

Conventions: world frame in metres, z up, ground at z = 0; the default walk
goes along +x from the origin, on a trail kept free of trunks.  Sun azimuth is
measured from +x towards +y.  Radiometry: the sun's irradiance (W m^-2 on a
surface facing it) and the sky's share of it set the absolute scale; albedos
are those of the real materials (fresh snow 0.8-0.95, conifer needles and bark
0.02-0.15, forest litter 0.03-0.25).  The sun is a directional emitter, except
in ``sun_glare`` where it must show in the image (a distant sphere of the sun's
angular size carrying the same irradiance); the sky is an environment map
holding ``sky_fraction`` of the sun's irradiance.  The path tracer stops after
one indirect bounce (``max_depth`` 3), which keeps renders fast and leaves
multiply-reflected light out: measured against ``max_depth`` 6 at 96x60, shade
is 3 % darker in ``forest_winter`` and 20 % darker inside the ``forest_edge``
stand, which moves the dynamic range by less than 1 dB.

Dynamic range comes from the physics, not from exposure tricks: sunlit snow
(~160 W m^-2 sr^-1) against needles and bark lit by a little sky or by light
bounced once.  ``forest_edge`` closes the sky off entirely with a roof of
needles; what little daylight a dense canopy passes is modelled as a faint
downward emission of that roof (``canopy_transmittance``), which keeps the
inside dark but sampled without the noise of light that only enters through
the opening.
"""

from __future__ import annotations

import math

import numpy as np

from scenes import textures as tx
from scenes.base import register_scene
from scenes.description import Material, SceneDescription, Shape, Sun
from scenes.errors import SceneError
from scenes.geometry import MeshData, box, icosphere, merge, prisms, quad, scatter_points
from scenes.geometry import whorls as branch_whorls
from scenes.lighting import SUN_ANGULAR_DIAMETER_DEG, daylight_rgb, sky_envmap, sun_direction

__all__ = ["forest_winter", "forest_summer", "sun_glare", "forest_edge", "static_lab"]

# Purposes of the independent random streams of a scene: changing the tree
# density must not change the snow texture, and so on.
_TEXTURES, _TREES, _ROCKS, _CANOPY, _DETAIL = 1, 2, 3, 4, 5

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

def _snow_material(albedo: np.ndarray, rng: np.random.Generator, detail_px: int) -> Material:
    """Snow: metre-scale albedo, centimetre-scale litter and grain, bump-mapped crust."""
    if detail_px < 64 or detail_px > 4096:
        raise SceneError(f"detail_px must be in [64, 4096], got {detail_px}")
    relief = tx.relief(rng, int(SNOW_RELIEF["size"]), beta=float(SNOW_RELIEF["beta"]))
    return Material("diffuse", albedo, detail=tx.snow_detail(rng, detail_px, tile_m=_DETAIL_TILE_M, **SNOW_DETAIL),
                    detail_repeat=_GROUND_TILE_M / _DETAIL_TILE_M, detail_range=SNOW_DETAIL_RANGE,
                    bump=relief, bump_repeat=_GROUND_TILE_M / _DETAIL_TILE_M,
                    bump_amplitude=float(SNOW_RELIEF["amplitude_m"]))


def _bark_material(albedo: np.ndarray, rng: np.random.Generator) -> Material:
    """Bark (1 m texture repeats): plates and cracks."""
    return Material("diffuse", albedo, detail=tx.bark_detail(rng), detail_repeat=2.0, detail_range=BARK_DETAIL_RANGE)


def _needle_material(albedo: np.ndarray, rng: np.random.Generator) -> Material:
    """Spruce foliage (1 m texture repeats): needle clumps over 2 m tiles, dark gaps."""
    return Material("diffuse", albedo, detail=tx.needle_clumps(rng, 512, tile_m=2.0, **NEEDLE_DETAIL),
                    detail_repeat=0.5, detail_range=NEEDLE_DETAIL_RANGE)


def _rng(seed: int, purpose: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), purpose])


def _require(scene: str, p: dict, key: str, lo: float, hi: float) -> float:
    v = p[key]
    if not lo <= v <= hi:
        raise SceneError(f"{scene}: parameter {key} must be in [{lo}, {hi}], got {v!r}")
    return v


def _daylight(scene: str, p: dict, *, disk_visible: bool = False) -> tuple[Sun, np.ndarray, float]:
    _require(scene, p, "sun_elevation_deg", 0.5, 90.0)
    _require(scene, p, "sun_irradiance_w_m2", 1e-3, 1e5)
    _require(scene, p, "sky_fraction", 0.0, 1.0)
    _require(scene, p, "sun_cct_k", 4000.0, 25000.0)
    _require(scene, p, "sky_cct_k", 4000.0, 25000.0)
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


def _ground(half_size_m: float, texture_scale_m: float, x0: float = 0.0, x1: float | None = None) -> MeshData:
    """Horizontal ground quad (normal +z) over x in [x0 - half, x1 or x0 + half], |y| <= half."""
    xa = x0 - half_size_m if x1 is None else x0
    xb = x0 + half_size_m if x1 is None else x1
    return quad((xa, -half_size_m, 0.0), (xb - xa, 0.0, 0.0), (0.0, 2 * half_size_m, 0.0),
                texture_scale_m=texture_scale_m)


def _conifer_stand(rng: np.random.Generator, *, density_per_ha: float, x_range: tuple, y_range: tuple,
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


def _rocks(rng: np.random.Generator, count: int, x_range: tuple, y_range: tuple, trail_half_width_m: float,
           size_range: tuple = (0.3, 1.0)) -> MeshData | None:
    meshes = []
    for _ in range(count):
        x = rng.uniform(*x_range)
        y = rng.choice([-1.0, 1.0]) * rng.uniform(trail_half_width_m + 0.5, max(y_range) + 1e-9)
        r = rng.uniform(*size_range)
        meshes.append(icosphere((x, y, 0.1 * r), r, subdivisions=2, roughness=0.25, rng=rng, squash=0.6,
                                texture_scale_m=1.5))
    return merge(meshes) if meshes else None


def _backdrop(x_range: tuple, y_range: tuple, height_m: float) -> MeshData:
    """Four inward-facing walls of foliage closing the horizon around a stand (the forest goes on)."""
    (x0, x1), (y0, y1) = x_range, y_range
    return merge([
        quad((x1, y0, 0.0), (0.0, y1 - y0, 0.0), (0.0, 0.0, height_m), texture_scale_m=3.0),
        quad((x0, y1, 0.0), (0.0, y0 - y1, 0.0), (0.0, 0.0, height_m), texture_scale_m=3.0),
        quad((x0, y0, 0.0), (x1 - x0, 0.0, 0.0), (0.0, 0.0, height_m), texture_scale_m=3.0),
        quad((x1, y1, 0.0), (x0 - x1, 0.0, 0.0), (0.0, 0.0, height_m), texture_scale_m=3.0),
    ])


def _shapes(**named) -> list[Shape]:
    return [Shape("mesh", material=mat, mesh=mesh) for mat, mesh in named.items() if mesh is not None]


# --------------------------------------------------------------------------------------------
# forest_winter
# --------------------------------------------------------------------------------------------

def _describe_forest_winter(seed: int, p: dict) -> SceneDescription:
    name = "forest_winter"
    sun, sky, ref = _daylight(name, p)
    _require(name, p, "tree_density_per_ha", 0.0, 3000.0)
    _require(name, p, "trail_half_width_m", 0.5, 20.0)
    px = p["texture_px"]
    if px < 64 or px > 4096:
        raise SceneError(f"{name}: parameter texture_px must be in [64, 4096], got {px}")
    rt = _rng(seed, _TEXTURES)
    rd = _rng(seed, _DETAIL)
    materials = {
        "snow": _snow_material(tx.snow_texture(rt, px), rd, p["detail_px"]),
        "bark": _bark_material(tx.bark_texture(rt), rd),
        "needles": _needle_material(tx.foliage_texture(rt, low=NEEDLE_ALBEDO[0], high=NEEDLE_ALBEDO[1]), rd),
        "rock": Material("diffuse", tx.rock_texture(rt)),
    }
    trunks, crowns, _ = _conifer_stand(_rng(seed, _TREES), density_per_ha=p["tree_density_per_ha"],
                                       x_range=(-15.0, 90.0), y_range=(-35.0, 35.0),
                                       trail_half_width_m=p["trail_half_width_m"])
    rocks = _rocks(_rng(seed, _ROCKS), 12, (-5.0, 80.0), (-12.0, 12.0), p["trail_half_width_m"])
    shapes = _shapes(snow=_ground(300.0, 12.0), bark=trunks, needles=crowns, rock=rocks)
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


# --------------------------------------------------------------------------------------------
# forest_summer
# --------------------------------------------------------------------------------------------

def _describe_forest_summer(seed: int, p: dict) -> SceneDescription:
    name = "forest_summer"
    sun, sky, ref = _daylight(name, p)
    _require(name, p, "canopy_density_per_ha", 0.0, 3000.0)
    _require(name, p, "trail_half_width_m", 0.5, 20.0)
    px = p["texture_px"]
    if px < 64 or px > 4096:
        raise SceneError(f"{name}: parameter texture_px must be in [64, 4096], got {px}")
    rt = _rng(seed, _TEXTURES)
    materials = {
        "litter": Material("diffuse", tx.litter_texture(rt, px)),
        "bark": Material("diffuse", tx.bark_texture(rt, low=0.05, high=0.25)),
        "leaves": Material("diffuse", tx.foliage_texture(rt, low=0.04, high=0.16, colour=(0.5, 1.0, 0.35))),
        "shrub": Material("diffuse", tx.foliage_texture(rt, low=0.03, high=0.12, colour=(0.45, 1.0, 0.3))),
        "rock": Material("diffuse", tx.rock_texture(rt)),
    }
    rng = _rng(seed, _TREES)
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
    rs = _rng(seed, _CANOPY)
    for x, y in scatter_points(rs, x_range=(-10.0, 85.0), y_range=(-15.0, 15.0), density_per_m2=0.02,
                               min_distance_m=1.5, keep=lambda xy: np.abs(xy[:, 1]) > half + 0.6):
        r = rs.uniform(0.3, 0.8)
        shrubs.append(icosphere((x, y, 0.6 * r), r, subdivisions=1, roughness=0.35, rng=rs, squash=0.8,
                                texture_scale_m=0.7))
    rocks = _rocks(_rng(seed, _ROCKS), 10, (-5.0, 80.0), (-10.0, 10.0), half)
    backdrop = _backdrop((-25.0, 110.0), (-40.0, 40.0), 10.0)
    trunks = None
    if trunk_rows:
        t = np.array(trunk_rows)
        trunks = prisms(np.stack([t[:, 0], t[:, 1], np.full(len(t), -0.1)], -1), t[:, 2], t[:, 3], tapers=0.5,
                        phases=t[:, 4], texture_scale_m=1.0)
    shapes = _shapes(litter=_ground(300.0, 10.0), bark=trunks,
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


# --------------------------------------------------------------------------------------------
# sun_glare
# --------------------------------------------------------------------------------------------

def _describe_sun_glare(seed: int, p: dict) -> SceneDescription:
    name = "sun_glare"
    sun, sky, ref = _daylight(name, p, disk_visible=True)
    _require(name, p, "tree_density_per_ha", 0.0, 3000.0)
    _require(name, p, "ice_roughness", 0.005, 1.0)
    px = p["texture_px"]
    if px < 64 or px > 4096:
        raise SceneError(f"{name}: parameter texture_px must be in [64, 4096], got {px}")
    rt = _rng(seed, _TEXTURES)
    ice_noise = tx.fractal_noise((256, 256), rt, beta=2.0)
    materials = {
        "snow": Material("diffuse", tx.snow_texture(rt, px)),
        "bark": Material("diffuse", tx.bark_texture(rt)),
        "needles": Material("diffuse", tx.foliage_texture(rt)),
        "ice": Material("roughplastic", tx.albedo_map(ice_noise, 0.04, 0.2, (0.85, 0.95, 1.0)),
                        roughness=p["ice_roughness"], ior=1.31),
    }
    trunks, crowns, _ = _conifer_stand(_rng(seed, _TREES), density_per_ha=p["tree_density_per_ha"],
                                       x_range=(-15.0, 120.0), y_range=(-35.0, 35.0), trail_half_width_m=1.5,
                                       keep=lambda xy: (np.abs(xy[:, 1]) > 1.9)
                                       & ~((xy[:, 0] > p["ice_start_m"] - 2) & (xy[:, 0] < p["ice_start_m"] + 27)
                                           & (np.abs(xy[:, 1]) < 10)))
    x0 = p["ice_start_m"]
    pond = quad((x0, -7.0, 0.005), (25.0, 0.0, 0.0), (0.0, 14.0, 0.0), texture_scale_m=6.0)
    shapes = _shapes(snow=_ground(300.0, 12.0), bark=trunks, needles=crowns, ice=pond)
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


# --------------------------------------------------------------------------------------------
# forest_edge
# --------------------------------------------------------------------------------------------

def _describe_forest_edge(seed: int, p: dict) -> SceneDescription:
    name = "forest_edge"
    sun, sky, ref = _daylight(name, p)
    _require(name, p, "exit_x_m", 1.0, 500.0)
    _require(name, p, "tunnel_length_m", 5.0, 500.0)
    _require(name, p, "roof_gap_fraction", 0.0, 0.5)
    _require(name, p, "tunnel_half_width_m", 1.0, 20.0)
    _require(name, p, "canopy_height_m", 2.5, 30.0)
    _require(name, p, "canopy_transmittance", 0.0, 0.2)
    px = p["texture_px"]
    if px < 64 or px > 4096:
        raise SceneError(f"{name}: parameter texture_px must be in [64, 4096], got {px}")
    rt = _rng(seed, _TEXTURES)
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
    litter = _ground(60.0, 6.0, x0=x_back - 5.0, x1=ex)
    snow = _ground(300.0, 12.0, x0=ex, x1=ex + 300.0)
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
    rr = _rng(seed, _CANOPY)
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
    rt2 = _rng(seed, _TREES)
    trunks = []
    for side in (-1.0, 1.0):
        xy = scatter_points(rt2, x_range=(x_back + 1.0, ex - 0.5), y_range=(1.4, w - 0.3), density_per_m2=0.25,
                            min_distance_m=0.9)
        if len(xy):
            trunks.append(prisms(np.stack([xy[:, 0], side * xy[:, 1], np.full(len(xy), -0.1)], -1),
                                 rt2.uniform(0.08, 0.22, len(xy)), h + 0.2, tapers=0.8,
                                 phases=rt2.uniform(0, 2 * np.pi, len(xy)), texture_scale_m=1.0))
    far_trunks, far_crowns, _ = _conifer_stand(rt2, density_per_ha=300.0, x_range=(ex + 60.0, ex + 110.0),
                                               y_range=(-80.0, 80.0), trail_half_width_m=0.0,
                                               keep=lambda xy: np.ones(len(xy), bool))
    shapes = _shapes(litter=litter, snow=snow, needles=merge(foliage + ([far_crowns] if far_crowns else [])),
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


# --------------------------------------------------------------------------------------------
# static_lab
# --------------------------------------------------------------------------------------------

def _look_at_rect(center, target, size_m: float) -> np.ndarray:
    """to_world of a Mitsuba rectangle ([-1, 1]^2, normal +z) of side ``size_m`` facing ``target``."""
    c, t = np.asarray(center, float), np.asarray(target, float)
    z = (t - c) / np.linalg.norm(t - c)
    up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x * size_m / 2, y * size_m / 2, z, c
    return m


def _describe_static_lab(seed: int, p: dict) -> SceneDescription:
    name = "static_lab"
    _require(name, p, "light_irradiance_w_m2", 1e-3, 1e5)
    _require(name, p, "light_cct_k", 4000.0, 25000.0)
    _require(name, p, "albedo_min", 0.002, 0.5)
    _require(name, p, "albedo_max", 0.05, 1.0)
    if p["albedo_min"] >= p["albedo_max"]:
        raise SceneError(f"{name}: albedo_min must be below albedo_max")
    rows, cols = p["chart_rows"], p["chart_cols"]
    if not (1 <= rows <= 16 and 1 <= cols <= 16):
        raise SceneError(f"{name}: chart_rows and chart_cols must be in 1..16, got {rows}, {cols}")
    rt = _rng(seed, _TEXTURES)
    n = rows * cols
    ramp = p["albedo_max"] * (p["albedo_min"] / p["albedo_max"]) ** (np.arange(n) / max(n - 1, 1))
    # a fixed scrambled layout (stride coprime with n): every region of the chart, the
    # lit part and the fin's shadow, holds bright and dark patches whatever the seed
    stride = next(k for k in range(max(2, math.isqrt(n)), n + 2) if math.gcd(k, n) == 1)
    albedos = ramp[(np.arange(n) * stride) % n].reshape(rows, cols)
    lab_grey = tx.albedo_map(tx.fractal_noise((256, 256), rt, beta=1.5), 0.25, 0.55, (1.0, 1.0, 1.0))
    floor_tex = tx.albedo_map(tx.fractal_noise((256, 256), rt, beta=1.2), 0.08, 0.3, (1.0, 0.95, 0.9))
    materials = {
        "chart": Material("diffuse", tx.chart_texture(rt, albedos), two_sided=False),
        "wall": Material("diffuse", lab_grey),
        "floor": Material("diffuse", floor_tex),
        "black": Material("diffuse", (0.03, 0.03, 0.03)),
        "props": Material("diffuse", tx.rock_texture(rt, 128)),
    }
    # room: x in [-1.5, 4], y in [-2.5, 2.5], z in [0, 3]; camera at (0, 0, 1.4) looking +x
    x0, x1, y0, y1, z1 = -1.5, 4.0, -2.5, 2.5, 3.0
    walls = merge([
        quad((x1, y1, 0.0), (0.0, y0 - y1, 0.0), (0.0, 0.0, z1), texture_scale_m=1.0),  # back wall, faces -x
        quad((x0, y0, 0.0), (0.0, y1 - y0, 0.0), (0.0, 0.0, z1), texture_scale_m=1.0),  # wall behind camera
        quad((x0, y1, 0.0), (x1 - x0, 0.0, 0.0), (0.0, 0.0, z1), texture_scale_m=1.0),  # left wall (+y)
        quad((x1, y0, 0.0), (x0 - x1, 0.0, 0.0), (0.0, 0.0, z1), texture_scale_m=1.0),  # right wall (-y)
        quad((x0, y0, z1), (0.0, y1 - y0, 0.0), (x1 - x0, 0.0, 0.0), texture_scale_m=1.0),  # ceiling
    ])
    floor = quad((x0, y0, 0.0), (x1 - x0, 0.0, 0.0), (0.0, y1 - y0, 0.0), texture_scale_m=1.0)
    # chart on the back wall: 2.4 m x 1.6 m centred at (x1 - 0.01, 0, 1.4), facing -x
    cw, ch = 2.4, 1.6
    chart = quad((x1 - 0.01, cw / 2, 1.4 - ch / 2), (0.0, -cw, 0.0), (0.0, 0.0, ch), texture_scale_m=1.0)
    chart = type(chart)(chart.vertices, chart.faces, (chart.uvs / chart.uvs.max(axis=0)).astype(np.float32))
    # lamp: a 0.4 m square softbox high on the left, aimed at the chart centre
    lamp_pos, target, side = np.array([1.2, 1.6, 2.6]), np.array([x1, 0.0, 1.4]), 0.4
    d = target - lamp_pos
    dist = float(np.linalg.norm(d))
    cos_chart = abs(d[0]) / dist
    radiance = p["light_irradiance_w_m2"] * dist ** 2 / (side * side * cos_chart)
    lamp_rgb = tuple(float(v) * radiance for v in daylight_rgb(p["light_cct_k"]))
    # a fin (thin black panel standing out of the wall at the chart's centre) shades the
    # lower right of the chart from the lamp; two props on the floor
    fin = box((x1 - 0.8, -0.02, 0.0), (x1 - 0.01, 0.02, 1.5))
    props = merge([box((2.6, -1.3, 0.0), (3.2, -0.7, 0.5), texture_scale_m=0.5),
                   icosphere((2.8, 0.9, 0.35), 0.35, subdivisions=2, texture_scale_m=0.5)])
    shapes = [
        Shape("mesh", material="wall", mesh=walls), Shape("mesh", material="floor", mesh=floor),
        Shape("mesh", material="chart", mesh=chart), Shape("mesh", material="black", mesh=fin),
        Shape("mesh", material="props", mesh=props),
        Shape("rectangle", material="black", to_world=_look_at_rect(lamp_pos, target, side), radiance=lamp_rgb),
    ]
    return SceneDescription(materials=materials, shapes=tuple(shapes), sun=None, sky=None,
                            max_depth=p["max_depth"], reference_radiance=p["light_irradiance_w_m2"] / math.pi,
                            notes={"chart_albedos": albedos.tolist()})


@register_scene(_describe_static_lab, is_static=True, start=(0.0, 0.0))
def static_lab(
    seed: int = 0,
    *,
    light_irradiance_w_m2: float = 1000.0,
    light_cct_k: float = 5500.0,
    albedo_min: float = 0.01,
    albedo_max: float = 0.9,
    chart_rows: int = 4,
    chart_cols: int = 6,
    max_depth: int = 3,
):
    """A static lab: a textured patch chart of log-spaced albedos under one softbox, part in shade.

    For the emulator validation of paper section V-B: a fixed camera, fixed
    radiance, a wide spread of albedos (0.9 to 0.01, 39 dB) times the lamp's
    fall-off and a fin's shadow, so that every bracket of 1..32 ms has both
    well-exposed and clipped or dark pixels.

    Parameters
    ----------
    seed : int
        Textures (the patch layout is fixed).
    light_irradiance_w_m2 : float
        Irradiance of the lamp at the chart centre, W m^-2 (default: sun-like,
        so one camera gain fits the outdoor scenes too).
    light_cct_k : float
        Colour temperature of the lamp, K (CIE daylight).
    albedo_min, albedo_max : float
        Darkest and brightest patch albedo (log-spaced in between).
    chart_rows, chart_cols : int
        Patch grid.
    max_depth : int
        Path length limit of the path tracer.
    """
