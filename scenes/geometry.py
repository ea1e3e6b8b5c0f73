"""Triangle meshes and object placement in numpy (no Mitsuba here).

All geometry is in the world frame: metres, z up, ground at z = 0.  Meshes
carry per-vertex texture coordinates in texture repeats, so a bitmap applied to
them tiles at a physical scale.  Many objects of one material are merged into
one :class:`MeshData`, which keeps the Mitsuba scene small and fast to load.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from scenes.errors import SceneError

__all__ = [
    "MeshData",
    "merge",
    "cone",
    "cones",
    "whorls",
    "prism",
    "prisms",
    "icosphere",
    "box",
    "quad",
    "scatter_points",
]


@dataclass(frozen=True)
class MeshData:
    """A triangle mesh.

    Attributes
    ----------
    vertices : numpy.ndarray
        float32 (N, 3) positions, metres.
    faces : numpy.ndarray
        uint32 (M, 3) vertex indices, counter-clockwise seen from outside.
    uvs : numpy.ndarray
        float32 (N, 2) texture coordinates (in texture repeats).
    """

    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray

    def __post_init__(self) -> None:
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise SceneError(f"MeshData: vertices must be (N, 3), got {self.vertices.shape}")
        if self.uvs.shape != (self.vertices.shape[0], 2):
            raise SceneError(f"MeshData: uvs must be (N, 2), got {self.uvs.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise SceneError(f"MeshData: faces must be (M, 3), got {self.faces.shape}")
        if self.faces.size and int(self.faces.max()) >= self.vertices.shape[0]:
            raise SceneError("MeshData: a face indexes a missing vertex")

    @property
    def face_count(self) -> int:
        return int(self.faces.shape[0])


def _mesh(vertices, faces, uvs) -> MeshData:
    return MeshData(
        np.ascontiguousarray(vertices, dtype=np.float32),
        np.ascontiguousarray(faces, dtype=np.uint32),
        np.ascontiguousarray(uvs, dtype=np.float32),
    )


def merge(meshes: list[MeshData]) -> MeshData:
    """Concatenate meshes into one (faces re-indexed)."""
    if not meshes:
        raise SceneError("merge: no meshes to merge")
    offsets = np.cumsum([0] + [m.vertices.shape[0] for m in meshes[:-1]])
    return _mesh(
        np.concatenate([m.vertices for m in meshes]),
        np.concatenate([m.faces.astype(np.int64) + o for m, o in zip(meshes, offsets)]),
        np.concatenate([m.uvs for m in meshes]),
    )


def _rings(centers: np.ndarray, radii: np.ndarray, segments: int, phases: np.ndarray) -> np.ndarray:
    """(N, segments + 1, 3) horizontal circles (seam point duplicated)."""
    a = phases[:, None] + 2.0 * np.pi * np.arange(segments + 1)[None, :] / segments
    return np.stack([centers[:, 0:1] + radii[:, None] * np.cos(a), centers[:, 1:2] + radii[:, None] * np.sin(a),
                     np.broadcast_to(centers[:, 2:3], a.shape)], axis=-1)


def _bands(bottom: np.ndarray, top: np.ndarray, v1: np.ndarray, u_repeats: np.ndarray) -> MeshData:
    """N bands of quads between pairs of rings (N, S + 1, 3); texture v from 0 (bottom) to v1."""
    n_obj, n1, _ = bottom.shape
    n = n1 - 1
    verts = np.concatenate([bottom, top], axis=1).reshape(-1, 3)
    u = u_repeats[:, None] * np.arange(n1)[None, :] / n
    uvs = np.concatenate([np.stack([u, np.zeros_like(u)], -1), np.stack([u, np.broadcast_to(v1[:, None], u.shape)],
                                                                        -1)], axis=1).reshape(-1, 2)
    i = np.arange(n)
    a, b, c, d = i, i + 1, n1 + i + 1, n1 + i
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)])
    faces = (faces[None, :, :] + (2 * n1 * np.arange(n_obj))[:, None, None]).reshape(-1, 3)
    return _mesh(verts, faces, uvs)


def _as_n(x, n: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(x, dtype=np.float64), (n,)).copy()


def cones(base_centers, radii, heights, *, phases=0.0, segments: int = 12, texture_scale_m: float = 1.0) -> MeshData:
    """Many open cones (side only), vertical axes, apex above the base: one mesh.

    The missing base leaves the underside hollow, which is how the underside of a
    spruce whorl looks: a dark cavity.  Render them two-sided.

    Parameters
    ----------
    base_centers : array-like
        (N, 3) centres of the base circles, metres.
    radii, heights : array-like
        (N,) base radii and heights, metres (> 0).
    phases : float or array-like
        Rotation of the facets about each axis, radians.
    segments : int
        Facets around.
    texture_scale_m : float
        Metres per texture repeat along the slant and around.
    """
    c = np.atleast_2d(np.asarray(base_centers, dtype=np.float64))
    n = c.shape[0]
    r, h, ph = _as_n(radii, n), _as_n(heights, n), _as_n(phases, n)
    if np.any(r <= 0) or np.any(h <= 0):
        raise SceneError("cones: radii and heights must be > 0")
    bottom = _rings(c, r, segments, ph)
    top = _rings(c + np.stack([np.zeros(n), np.zeros(n), h], -1), 1e-3 * r, segments, ph)
    slant = np.hypot(r, h)
    return _bands(bottom, top, slant / texture_scale_m, np.maximum(1.0, np.round(2 * np.pi * r / texture_scale_m)))


def whorls(base_centers, radii, heights, *, rng: np.random.Generator, branches: tuple[int, int] = (9, 15),
           notch: tuple[float, float] = (0.35, 0.6), droop: float = 0.25, texture_scale_m: float = 1.0) -> MeshData:
    """Spruce branch whorls: open cones whose rim is a star of branch tips and notches.

    Each whorl is a cone from a star-shaped rim (``2 n`` vertices: ``n`` branch
    tips at ``radius * U(0.8, 1.0)``, drooping ``droop * height`` below the base,
    and ``n`` notches at ``radius * U(notch)``) through a smaller star at mid
    height to the apex.  The silhouette and the shadows it casts are jagged at
    the scale of single branches (tens of centimetres), where a smooth cone has
    one long edge.  Render two-sided.

    Parameters
    ----------
    base_centers : array-like
        (N, 3) centres of the rims, metres.
    radii, heights : array-like
        (N,) rim radii and heights (rim to apex), metres (> 0).
    rng : numpy.random.Generator
        Branch counts, lengths and angles.
    branches : tuple of int
        Range of branches per whorl (inclusive).
    notch : tuple of float
        Range of the notch radius as a fraction of the whorl radius.
    droop : float
        How far branch tips hang below the rim, as a fraction of the height.
    texture_scale_m : float
        Metres per texture repeat along the slant and around.
    """
    c = np.atleast_2d(np.asarray(base_centers, dtype=np.float64))
    n_obj = c.shape[0]
    r, h = _as_n(radii, n_obj), _as_n(heights, n_obj)
    if np.any(r <= 0) or np.any(h <= 0):
        raise SceneError("whorls: radii and heights must be > 0")
    verts, faces, uvs = [], [], []
    offset = 0
    for i in range(n_obj):
        nb = int(rng.integers(branches[0], branches[1] + 1))
        m = 2 * nb
        ang = rng.uniform(0, 2 * np.pi) + 2 * np.pi * (np.arange(m) + rng.uniform(-0.25, 0.25, m)) / m
        tip = np.arange(m) % 2 == 0
        frac = np.where(tip, rng.uniform(0.8, 1.0, m), rng.uniform(*notch, m))
        rim_r = r[i] * frac
        rim_z = np.where(tip, -droop * h[i] * rng.uniform(0.5, 1.0, m), 0.0)
        mid_r = 0.5 * rim_r * rng.uniform(0.85, 1.1, m)
        # rings of m + 1 vertices: the last repeats the first one turn later (texture seam)
        a1 = np.append(ang, ang[0] + 2 * np.pi)
        rim_r, rim_z, mid_r = (np.append(x, x[0]) for x in (rim_r, rim_z, mid_r))

        def ring(rr, zz):
            return np.stack([c[i, 0] + rr * np.cos(a1), c[i, 1] + rr * np.sin(a1), c[i, 2] + zz], -1)

        n1 = m + 1
        v = np.concatenate([ring(rim_r, rim_z), ring(mid_r, np.full(n1, 0.45 * h[i])),
                            [[c[i, 0], c[i, 1], c[i, 2] + h[i]]]])
        k = np.arange(m)
        f = np.concatenate([np.stack([k, k + 1, n1 + k + 1], -1), np.stack([k, n1 + k + 1, n1 + k], -1),
                            np.stack([n1 + k, n1 + k + 1, np.full(m, 2 * n1)], -1)])
        slant = np.hypot(r[i], h[i])
        u = np.concatenate([a1, a1, [a1[0]]]) * r[i] / texture_scale_m
        vv = np.concatenate([np.zeros(n1), np.full(n1, 0.5 * slant), [slant]]) / texture_scale_m
        verts.append(v)
        faces.append(f + offset)
        uvs.append(np.stack([u, vv], -1))
        offset += v.shape[0]
    return _mesh(np.concatenate(verts), np.concatenate(faces), np.concatenate(uvs))


def prisms(bases, radii, heights, *, tapers=1.0, phases=0.0, segments: int = 10,
           texture_scale_m: float = 1.0) -> MeshData:
    """Many vertical open cylinders (trunks), each from a base point up by a height: one mesh.

    ``tapers`` is the top radius as a fraction of the bottom radius.
    """
    c = np.atleast_2d(np.asarray(bases, dtype=np.float64))
    n = c.shape[0]
    r, h, tp, ph = _as_n(radii, n), _as_n(heights, n), _as_n(tapers, n), _as_n(phases, n)
    if np.any(r <= 0) or np.any(h <= 0):
        raise SceneError("prisms: radii and heights must be > 0")
    bottom = _rings(c, r, segments, ph)
    top = _rings(c + np.stack([np.zeros(n), np.zeros(n), h], -1), tp * r, segments, ph)
    return _bands(bottom, top, h / texture_scale_m, np.maximum(1.0, np.round(2 * np.pi * r / texture_scale_m)))


def cone(base_center, radius: float, height: float, *, segments: int = 12, phase: float = 0.0,
         texture_scale_m: float = 1.0) -> MeshData:
    """One open cone: see :func:`cones`."""
    if radius <= 0 or height <= 0:
        raise SceneError(f"cone: radius and height must be > 0, got {radius}, {height}")
    return cones([base_center], [radius], [height], phases=phase, segments=segments,
                 texture_scale_m=texture_scale_m)


def prism(p0, radius: float, height: float, *, segments: int = 10, phase: float = 0.0, taper: float = 1.0,
          texture_scale_m: float = 1.0) -> MeshData:
    """One vertical open cylinder: see :func:`prisms`."""
    if radius <= 0 or height <= 0:
        raise SceneError(f"prism: radius and height must be > 0, got {radius}, {height}")
    return prisms([p0], [radius], [height], tapers=taper, phases=phase, segments=segments,
                  texture_scale_m=texture_scale_m)


@functools.lru_cache(maxsize=8)
def _unit_icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (unit vectors) and faces of a subdivided icosahedron (cached, read-only)."""
    t = (1.0 + 5.0 ** 0.5) / 2.0
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
             (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
             (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    v = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in verts]
    f = list(faces)
    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}

        def mid(i: int, j: int) -> int:
            key = (min(i, j), max(i, j))
            if key not in cache:
                m = v[i] + v[j]
                v.append(m / np.linalg.norm(m))
                cache[key] = len(v) - 1
            return cache[key]

        f = [g for a, b, c in f for g in ((a, mid(a, b), mid(a, c)), (b, mid(b, c), mid(a, b)),
                                          (c, mid(a, c), mid(b, c)), (mid(a, b), mid(b, c), mid(a, c)))]
    unit, faces = np.array(v), np.array(f, dtype=np.int64)
    unit.setflags(write=False)
    faces.setflags(write=False)
    return unit, faces


def icosphere(center, radius: float, *, subdivisions: int = 2, roughness: float = 0.0,
              rng: np.random.Generator | None = None, squash: float = 1.0,
              texture_scale_m: float = 1.0) -> MeshData:
    """Sphere mesh, optionally lumpy (rocks, leaf clusters).

    Parameters
    ----------
    center : array-like
        (3,) centre, metres.
    radius : float
        Radius, metres.
    subdivisions : int
        Subdivisions of an icosahedron (2 gives 320 faces).
    roughness : float
        Relative radial displacement amplitude (needs ``rng``).
    squash : float
        Vertical scale factor (< 1 flattens: a boulder, a crown layer).
    texture_scale_m : float
        Metres per texture repeat (planar projection on x/y and z).
    """
    unit, faces = _unit_icosphere(int(subdivisions))
    r = np.full(unit.shape[0], float(radius))
    if roughness > 0.0:
        if rng is None:
            raise SceneError("icosphere: roughness needs an rng")
        # smooth lumps: a few random low-order bumps
        for _ in range(6):
            axis = rng.standard_normal(3)
            axis /= np.linalg.norm(axis)
            r *= 1.0 + roughness * rng.uniform(-1, 1) * np.maximum(unit @ axis, 0.0) ** 2
    pos = unit * r[:, None]
    pos[:, 2] *= squash
    pos += np.asarray(center, dtype=np.float64)
    uv = np.stack([(pos[:, 0] + pos[:, 1]) / texture_scale_m, pos[:, 2] / texture_scale_m], -1)
    return _mesh(pos, faces, uv)


def quad(corner, edge_u, edge_v, *, texture_scale_m: float = 1.0) -> MeshData:
    """Planar quad ``corner + s*edge_u + t*edge_v``, s, t in [0, 1].

    The normal is ``edge_u x edge_v``.
    """
    c, eu, ev = (np.asarray(a, dtype=np.float64) for a in (corner, edge_u, edge_v))
    verts = np.stack([c, c + eu, c + eu + ev, c + ev])
    lu, lv = np.linalg.norm(eu) / texture_scale_m, np.linalg.norm(ev) / texture_scale_m
    uvs = np.array([[0, 0], [lu, 0], [lu, lv], [0, lv]])
    return _mesh(verts, np.array([[0, 1, 2], [0, 2, 3]]), uvs)


def box(lo, hi, *, texture_scale_m: float = 1.0) -> MeshData:
    """Closed axis-aligned box from corner ``lo`` to corner ``hi`` (outward normals)."""
    x0, y0, z0 = (float(a) for a in lo)
    x1, y1, z1 = (float(a) for a in hi)
    if not (x1 > x0 and y1 > y0 and z1 > z0):
        raise SceneError(f"box: need lo < hi on every axis, got {lo}, {hi}")
    dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
    s = texture_scale_m
    return merge([
        quad((x0, y0, z0), (0, dy, 0), (dx, 0, 0), texture_scale_m=s),  # bottom (-z)
        quad((x0, y0, z1), (dx, 0, 0), (0, dy, 0), texture_scale_m=s),  # top (+z)
        quad((x0, y0, z0), (dx, 0, 0), (0, 0, dz), texture_scale_m=s),  # -y
        quad((x1, y1, z0), (-dx, 0, 0), (0, 0, dz), texture_scale_m=s),  # +y
        quad((x0, y1, z0), (0, -dy, 0), (0, 0, dz), texture_scale_m=s),  # -x
        quad((x1, y0, z0), (0, dy, 0), (0, 0, dz), texture_scale_m=s),  # +x
    ])


def scatter_points(
    rng: np.random.Generator,
    *,
    x_range: tuple[float, float],
    y_range: tuple[float, float],
    density_per_m2: float,
    min_distance_m: float,
    keep=None,
) -> np.ndarray:
    """Random points with a minimum spacing (dart throwing), deterministic per rng.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the candidate positions.
    x_range, y_range : tuple of float
        Rectangle to fill, metres.
    density_per_m2 : float
        Target density of accepted points, per square metre.
    min_distance_m : float
        No two points closer than this.
    keep : callable, optional
        ``keep(xy) -> bool mask`` on candidate points (N, 2); rejected candidates
        are dropped (e.g. a trail kept free of trees).

    Returns
    -------
    numpy.ndarray
        float64 (K, 2) positions, K close to density * area (fewer when the
        spacing or ``keep`` does not allow it).
    """
    area = (x_range[1] - x_range[0]) * (y_range[1] - y_range[0])
    target = int(round(density_per_m2 * area))
    if target <= 0:
        return np.zeros((0, 2))
    cand = np.stack([rng.uniform(*x_range, 4 * target), rng.uniform(*y_range, 4 * target)], -1)
    if keep is not None:
        cand = cand[np.asarray(keep(cand), dtype=bool)]
    cell = max(min_distance_m, 1e-6)
    grid: dict[tuple[int, int], list[int]] = {}
    accepted: list[np.ndarray] = []
    for p in cand:
        if len(accepted) >= target:
            break
        gx, gy = int(np.floor(p[0] / cell)), int(np.floor(p[1] / cell))
        ok = True
        for ix in (gx - 1, gx, gx + 1):
            for iy in (gy - 1, gy, gy + 1):
                for k in grid.get((ix, iy), ()):
                    if np.hypot(*(accepted[k] - p)) < min_distance_m:
                        ok = False
                        break
                if not ok:
                    break
            if not ok:
                break
        if ok:
            grid.setdefault((gx, gy), []).append(len(accepted))
            accepted.append(p)
    return np.array(accepted).reshape(-1, 2)
