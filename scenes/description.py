"""A renderer-neutral description of a scene (numpy only).

Scene builders produce a :class:`SceneDescription`; ``scenes.mitsuba_objects`` turns it
into a Mitsuba scene dictionary.  Keeping the two apart means building a scene
(textures, geometry, daylight colours) never imports Mitsuba, and a test can
inspect a scene without rendering it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scenes.errors import SceneError
from scenes.geometry import MeshData

__all__ = ["Material", "Shape", "Sun", "SceneDescription"]

_MATERIAL_KINDS = ("diffuse", "roughplastic")
_SHAPE_KINDS = ("mesh", "rectangle", "sphere")


@dataclass(frozen=True)
class Material:
    """Surface reflectance.

    Attributes
    ----------
    kind : str
        ``"diffuse"`` (Lambertian) or ``"roughplastic"`` (diffuse base under a
        rough dielectric coat: ice, wet rock).
    albedo : numpy.ndarray or tuple
        Diffuse albedo: float32 (H, W, 3) texture in [0, 1], or an RGB triple.
    two_sided : bool
        Reflect on both faces (open meshes such as cones need it).
    roughness : float
        GGX alpha of the coat (``roughplastic`` only).
    ior : float
        Refractive index of the coat (``roughplastic`` only; ice 1.31).
    detail : numpy.ndarray or None
        Fine-scale albedo modulation (``diffuse`` only): float32 (h, w) in [0, 1],
        tiled ``detail_repeat`` times per repeat of ``albedo``.  The albedo becomes
        ``albedo * (lo + detail * (hi - lo))`` with ``(lo, hi) = detail_range``
        (rendered exactly, as a blend of two diffuse layers), so a texture of a few
        centimetres' period can ride on one of many metres without a huge bitmap.
    detail_repeat : float
        Detail tiles per albedo tile (> 0).
    detail_range : tuple of float
        Albedo factors at detail 0 and 1 (0 <= lo <= hi; ``albedo * hi`` is clipped to 1).
    bump : numpy.ndarray or None
        Micro-relief: float32 (h, w) height field in [0, 1], tiled ``bump_repeat``
        times per albedo tile, rendered as a bump map (shading normals only).
    bump_repeat : float
        Bump tiles per albedo tile (> 0).
    bump_amplitude : float
        Relief of the bump field, metres: heights are ``bump_amplitude * bump``
        (Mitsuba's ``bumpmap`` scale; the mesh texture coordinates are in metres
        over the mesh's ``texture_scale_m``, which Mitsuba's surface derivatives
        account for); 0 disables it.
    """

    kind: str
    albedo: np.ndarray | tuple
    two_sided: bool = True
    roughness: float = 0.1
    ior: float = 1.31
    detail: np.ndarray | None = None
    detail_repeat: float = 1.0
    detail_range: tuple = (1.0, 1.0)
    bump: np.ndarray | None = None
    bump_repeat: float = 1.0
    bump_amplitude: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in _MATERIAL_KINDS:
            raise SceneError(f"Material.kind must be one of {_MATERIAL_KINDS}, got {self.kind!r}")
        a = np.asarray(self.albedo)
        if not (a.shape == (3,) or (a.ndim == 3 and a.shape[2] == 3)):
            raise SceneError(f"Material.albedo must be RGB or (H, W, 3), got shape {a.shape}")
        if not np.all(np.isfinite(a)) or a.min() < 0 or a.max() > 1:
            raise SceneError("Material.albedo must be finite and in [0, 1]")
        for name in ("detail", "bump"):
            t = getattr(self, name)
            if t is None:
                continue
            t = np.asarray(t)
            if t.ndim != 2 or min(t.shape) < 2:
                raise SceneError(f"Material.{name} must be a 2-D (h, w) texture, got shape {t.shape}")
            if not np.all(np.isfinite(t)) or t.min() < 0 or t.max() > 1:
                raise SceneError(f"Material.{name} must be finite and in [0, 1]")
            if not (np.isfinite(getattr(self, f"{name}_repeat")) and getattr(self, f"{name}_repeat") > 0):
                raise SceneError(f"Material.{name}_repeat must be > 0")
        if self.detail is not None:
            if self.kind != "diffuse":
                raise SceneError("Material.detail is supported on diffuse materials only")
            lo, hi = (float(v) for v in self.detail_range)
            if not 0.0 <= lo <= hi:
                raise SceneError(f"Material.detail_range must satisfy 0 <= lo <= hi, got {self.detail_range!r}")
        if not (np.isfinite(self.bump_amplitude) and self.bump_amplitude >= 0):
            raise SceneError(f"Material.bump_amplitude must be >= 0, got {self.bump_amplitude!r}")


@dataclass(frozen=True)
class Shape:
    """One object of the scene.

    Attributes
    ----------
    kind : str
        ``"mesh"`` (``mesh``), ``"rectangle"`` (``to_world`` maps [-1, 1]^2 x {0},
        normal +z) or ``"sphere"`` (``center``, ``radius``).
    material : str or None
        Key into :attr:`SceneDescription.materials`; None for a pure emitter.
    radiance : tuple or None
        RGB radiance of an area emitter on this shape, W m^-2 sr^-1.
    """

    kind: str
    material: str | None = None
    mesh: MeshData | None = None
    to_world: np.ndarray | None = None
    center: tuple | None = None
    radius: float | None = None
    radiance: tuple | None = None

    def __post_init__(self) -> None:
        if self.kind not in _SHAPE_KINDS:
            raise SceneError(f"Shape.kind must be one of {_SHAPE_KINDS}, got {self.kind!r}")
        if self.kind == "mesh" and self.mesh is None:
            raise SceneError("Shape: a mesh shape needs mesh=")
        if self.kind == "rectangle" and (self.to_world is None or np.shape(self.to_world) != (4, 4)):
            raise SceneError("Shape: a rectangle needs a 4x4 to_world")
        if self.kind == "sphere" and (self.center is None or not self.radius or self.radius <= 0):
            raise SceneError("Shape: a sphere needs center= and radius > 0")
        if self.material is None and self.radiance is None:
            raise SceneError("Shape: needs a material, a radiance or both")


@dataclass(frozen=True)
class Sun:
    """The sun.

    Attributes
    ----------
    direction : numpy.ndarray
        (3,) unit vector from the scene towards the sun.
    irradiance_rgb : numpy.ndarray
        (3,) irradiance on a surface facing the sun, W m^-2 (luminance-scaled RGB).
    disk_visible : bool
        False: a directional (delta) emitter, invisible to the camera.  True: a
        sphere of the sun's angular diameter far away along ``direction``,
        carrying the same irradiance, so the disk shows in the image.
    angular_diameter_deg : float
        Apparent diameter of the disk (``disk_visible`` only).
    distance_m : float
        Distance of the disk sphere (``disk_visible`` only).
    """

    direction: np.ndarray
    irradiance_rgb: np.ndarray
    disk_visible: bool = False
    angular_diameter_deg: float = 0.533
    distance_m: float = 5000.0

    @property
    def disk_radiance_rgb(self) -> np.ndarray:
        """Radiance of the disk, W m^-2 sr^-1: irradiance / solid angle of the disk."""
        half = np.radians(self.angular_diameter_deg) / 2.0
        solid_angle = 2.0 * np.pi * (1.0 - np.cos(half))
        return np.asarray(self.irradiance_rgb, dtype=np.float64) / solid_angle


@dataclass(frozen=True)
class SceneDescription:
    """Everything the renderer needs, in numpy.

    Attributes
    ----------
    materials : dict
        Name -> :class:`Material`.
    shapes : tuple of Shape
        The objects.
    sun : Sun or None
        The sun, if any.
    sky : numpy.ndarray or None
        float32 (h, 2h, 3) environment map radiance (see :mod:`scenes.lighting`).
    max_depth : int
        Path length limit of the path tracer (3: direct light plus one bounce).
    reference_radiance : float
        Luminance of an ideal white Lambertian surface facing the main light,
        W m^-2 sr^-1; the synthetic camera can put its full well there at the
        shortest bracket.
    """

    materials: dict
    shapes: tuple
    sun: Sun | None
    sky: np.ndarray | None
    max_depth: int
    reference_radiance: float
    notes: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        for s in self.shapes:
            if s.material is not None and s.material not in self.materials:
                raise SceneError(f"SceneDescription: shape refers to unknown material {s.material!r}")
        if self.max_depth < 1:
            raise SceneError(f"max_depth must be >= 1, got {self.max_depth}")
