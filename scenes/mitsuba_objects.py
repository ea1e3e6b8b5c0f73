"""Translation of a :class:`~scenes.description.SceneDescription` into Mitsuba objects.

The only module besides :mod:`scenes.render` that imports Mitsuba, and
only inside functions, after :mod:`scenes.variant` has made sure the variant is
safe to load in this process.
"""

from __future__ import annotations

import math

import numpy as np

from scenes.camera import pose_to_mitsuba
from scenes.description import Material, SceneDescription
from scenes.lighting import ENVMAP_TO_WORLD

__all__ = ["scene_dict", "sensor_dict", "sampler_spp", "aov_integrator_dict", "INTEGRATOR", "SAMPLER", "AOVS"]

#: Path tracer; Russian roulette starts beyond max_depth, so noise is deterministic per seed.
INTEGRATOR = "path"
#: Correlated multi-jittered sampler (stratified): unbiased, and its noise falls
#: faster than 1/sqrt(spp) (measured on forest_winter at 120x75: about spp**-0.6,
#: 40 % less noise than the independent sampler at 256 spp).
SAMPLER = "multijitter"
#: Auxiliary images of the denoiser: first-hit diffuse reflectance and shading normal.
AOVS = "albedo:albedo,nn:sh_normal"


def aov_integrator_dict() -> dict:
    """Mitsuba ``aov`` integrator returning only the albedo (3) and normal (3) channels.

    No nested integrator: the pass traces primary rays only; the radiance comes
    from its own path-traced render.
    """
    return {"type": "aov", "aovs": AOVS}


def sampler_spp(spp: int) -> int:
    """Samples per pixel the multijitter sampler actually takes for a requested count.

    It stratifies the pixel into ``r x ceil(spp / r)`` cells with ``r = isqrt(spp)``,
    so counts that are not of that form are rounded up (8 -> 8, 10 -> 12,
    128 -> 132, 1000 -> 1023); perfect squares and ``n (n + 1)`` are kept.
    """
    spp = int(spp)
    r = max(1, math.isqrt(spp))
    return r * -(-spp // r)


def _transform(m: np.ndarray):
    import mitsuba as mi

    return mi.ScalarTransform4f(np.asarray(m, dtype=np.float64).tolist())


def _texture(albedo, repeat: float = 1.0):
    import mitsuba as mi

    a = np.asarray(albedo)
    if a.ndim == 1:
        return {"type": "rgb", "value": [float(v) for v in a]}
    if a.ndim == 2:
        a = a[..., None]
    d = {"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(a, dtype=np.float32)), "raw": True,
         "filter_type": "bilinear", "wrap_mode": "repeat"}
    if repeat != 1.0:
        d["to_uv"] = mi.ScalarTransform4f().scale([float(repeat), float(repeat), 1.0])
    return d


def _bsdf(mat: Material):
    import mitsuba as mi

    if mat.kind == "diffuse" and mat.detail is not None:
        # albedo * (lo + w (hi - lo)) exactly: diffuse reflection is linear in the albedo
        lo, hi = (float(v) for v in mat.detail_range)
        base = np.asarray(mat.albedo, dtype=np.float32)
        d = {"type": "blendbsdf", "weight": _texture(mat.detail, mat.detail_repeat),
             "bsdf_0": {"type": "diffuse", "reflectance": _texture(np.clip(base * lo, 0.0, 1.0))},
             "bsdf_1": {"type": "diffuse", "reflectance": _texture(np.clip(base * hi, 0.0, 1.0))}}
    elif mat.kind == "diffuse":
        d = {"type": "diffuse", "reflectance": _texture(mat.albedo)}
    else:  # roughplastic
        d = {"type": "roughplastic", "distribution": "ggx", "alpha": float(mat.roughness),
             "int_ior": float(mat.ior), "ext_ior": 1.0, "diffuse_reflectance": _texture(mat.albedo),
             "nonlinear": False}
    if mat.two_sided:
        d = {"type": "twosided", "bsdf": d}
    if mat.bump is not None and mat.bump_amplitude > 0:
        d = {"type": "bumpmap", "arbitrary": _texture(mat.bump, mat.bump_repeat),
             "scale": float(mat.bump_amplitude), "bsdf": d}
    return mi.load_dict(d)


def _mesh(name: str, data, bsdf, radiance=None, weight: float = 1.0):
    import mitsuba as mi

    props = mi.Properties()
    props["bsdf"] = bsdf
    if radiance is not None:
        # one-sided: emits on the side the counter-clockwise faces point to
        props["emitter"] = mi.load_dict(_weighted({"type": "area", "radiance": _rgb(radiance)}, weight))
    mesh = mi.Mesh(name, int(data.vertices.shape[0]), int(data.faces.shape[0]), props=props,
                   has_vertex_normals=False, has_vertex_texcoords=True)
    params = mi.traverse(mesh)
    ftype, utype = type(params["vertex_positions"]), type(params["faces"])
    params["vertex_positions"] = ftype(np.ascontiguousarray(data.vertices, dtype=np.float32).ravel())
    params["faces"] = utype(np.ascontiguousarray(data.faces, dtype=np.uint32).ravel())
    params["vertex_texcoords"] = ftype(np.ascontiguousarray(data.uvs, dtype=np.float32).ravel())
    params.update()
    return mesh


def _rgb(v) -> dict:
    return {"type": "rgb", "value": [float(x) for x in np.asarray(v, dtype=np.float64)]}


def _weighted(emitter: dict, weight: float) -> dict:
    """``emitter`` with Mitsuba's ``sampling_weight`` (omitted at 1, Mitsuba's default: the same scene bytes)."""
    return emitter if weight == 1.0 else {**emitter, "sampling_weight": float(weight)}


def scene_dict(desc: SceneDescription, emitter_weights: dict | None = None) -> dict:
    """Mitsuba scene dictionary (for ``mi.load_dict``) of a description, without a sensor.

    ``emitter_weights`` maps ``"sun"``, ``"sky"`` and ``"area"`` (every emitting shape) to the
    relative probability that next-event estimation picks that emitter (Mitsuba's
    ``sampling_weight``; default 1 each, Mitsuba's uniform choice).  The weights change the
    noise, not the expected radiance.
    """
    import mitsuba as mi

    w = {"sun": 1.0, "sky": 1.0, "area": 1.0, **(emitter_weights or {})}

    bsdfs = {name: _bsdf(mat) for name, mat in sorted(desc.materials.items())}
    d: dict = {"type": "scene", "integrator": {"type": INTEGRATOR, "max_depth": int(desc.max_depth),
                                               "rr_depth": int(desc.max_depth) + 1}}
    for i, shape in enumerate(desc.shapes):
        key = f"shape_{i:03d}"
        if shape.kind == "mesh":
            d[key] = _mesh(key, shape.mesh, bsdfs[shape.material], shape.radiance, w["area"])
            continue
        entry: dict
        if shape.kind == "rectangle":
            entry = {"type": "rectangle", "to_world": _transform(shape.to_world)}
        else:
            entry = {"type": "sphere", "center": [float(c) for c in shape.center], "radius": float(shape.radius)}
        if shape.material is not None:
            entry["bsdf"] = bsdfs[shape.material]
        if shape.radiance is not None:
            entry["emitter"] = _weighted({"type": "area", "radiance": _rgb(shape.radiance)}, w["area"])
        d[key] = entry
    if desc.sun is not None:
        sun = desc.sun
        direction = np.asarray(sun.direction, dtype=np.float64)
        if sun.disk_visible:
            half = math.radians(sun.angular_diameter_deg) / 2.0
            d["sun"] = {"type": "sphere", "center": [float(c) for c in direction * sun.distance_m],
                        "radius": float(sun.distance_m * math.sin(half)),
                        "emitter": _weighted({"type": "area", "radiance": _rgb(sun.disk_radiance_rgb)}, w["sun"])}
        else:
            d["sun"] = _weighted({"type": "directional", "direction": [float(c) for c in -direction],
                                  "irradiance": _rgb(sun.irradiance_rgb)}, w["sun"])
    if desc.sky is not None:
        d["sky"] = _weighted({"type": "envmap", "bitmap": mi.Bitmap(np.ascontiguousarray(desc.sky, dtype=np.float32)),
                              "to_world": _transform(ENVMAP_TO_WORLD)}, w["sky"])
    return d


def sensor_dict(pose, *, width: int, height: int, fov_deg: float, spp: int) -> dict:
    """Mitsuba perspective sensor for an OpenCV-frame camera-to-world pose.

    Box reconstruction filter (each sample lands in exactly one pixel) and a
    float32 RGB film.
    """
    return {
        "type": "perspective",
        "fov": float(fov_deg),
        "fov_axis": "x",
        "near_clip": 0.01,
        "far_clip": 1.0e5,
        "to_world": _transform(pose_to_mitsuba(pose)),
        "sampler": {"type": SAMPLER, "sample_count": int(spp)},
        "film": {"type": "hdrfilm", "width": int(width), "height": int(height), "rfilter": {"type": "box"},
                 "pixel_format": "rgb", "component_format": "float32"},
    }
