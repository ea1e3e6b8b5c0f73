"""``static_lab``: a static lab, a textured patch chart of log-spaced albedos under one softbox, part in shade."""

from __future__ import annotations

import math

import numpy as np

from scenes import textures as tx
from scenes.base import register_scene
from scenes.description import Material, SceneDescription, Shape
from scenes.errors import SceneError
from scenes.geometry import box, icosphere, merge, quad
from scenes.lighting import daylight_rgb
from scenes.library.parts import STREAM_TEXTURES, require_param, stream_rng

__all__ = ["static_lab"]


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
    require_param(name, p, "light_irradiance_w_m2", 1e-3, 1e5)
    require_param(name, p, "light_cct_k", 4000.0, 25000.0)
    require_param(name, p, "albedo_min", 0.002, 0.5)
    require_param(name, p, "albedo_max", 0.05, 1.0)
    if p["albedo_min"] >= p["albedo_max"]:
        raise SceneError(f"{name}: albedo_min must be below albedo_max")
    rows, cols = p["chart_rows"], p["chart_cols"]
    if not (1 <= rows <= 16 and 1 <= cols <= 16):
        raise SceneError(f"{name}: chart_rows and chart_cols must be in 1..16, got {rows}, {cols}")
    rt = stream_rng(seed, STREAM_TEXTURES)
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
