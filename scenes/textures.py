"""Procedural textures as numpy arrays (no Mitsuba here), made of the primitives of :mod:`scenes.texture_base`.

Every texture is a deterministic function of its arguments and a seed: spectral
(1/f^beta) fractal noise synthesised with an FFT, hence periodic, so it tiles
without seams when a surface repeats it.  The values are mapped to albedos with a
logarithmic ramp, because natural reflectance varies multiplicatively.  The
contrast they carry at every scale is what lets SIFT find features on snow, bark
and forest litter.
"""

from __future__ import annotations

import numpy as np

from scenes.errors import SceneError
from scenes.texture_base import albedo_map, as_rng, fractal_noise, sprinkle  # re-exported: the primitives live there

__all__ = [
    "fractal_noise",
    "albedo_map",
    "sprinkle",
    "snow_texture",
    "litter_texture",
    "bark_texture",
    "foliage_texture",
    "rock_texture",
    "chart_texture",
    "specks",
    "snow_detail",
    "litter_detail",
    "needle_clumps",
    "bark_detail",
    "relief",
]


def snow_texture(seed: int | np.random.Generator, size: int = 512) -> np.ndarray:
    """Snow albedo: bright (0.72..0.95), wind-packed ripples, fallen needles.

    Returns float32 (size, size, 3).
    """
    rng = as_rng(seed)
    coarse = fractal_noise((size, size), rng, beta=2.4, stretch=(1.0, 2.5))
    fine = fractal_noise((size, size), rng, beta=1.2)
    tex = albedo_map(0.65 * coarse + 0.35 * fine, 0.72, 0.95, (0.97, 0.99, 1.0))
    return sprinkle(tex, rng, density=0.0015, albedo=0.08, radius_px=1.5)


def litter_texture(seed: int | np.random.Generator, size: int = 512) -> np.ndarray:
    """Forest-floor litter (needles, leaves, soil): albedo 0.03..0.25, brown-green.

    Returns float32 (size, size, 3).
    """
    rng = as_rng(seed)
    coarse = fractal_noise((size, size), rng, beta=2.2)
    fine = fractal_noise((size, size), rng, beta=1.0)
    tex = albedo_map(0.5 * coarse + 0.5 * fine, 0.03, 0.25, (1.0, 0.85, 0.6))
    return sprinkle(tex, rng, density=0.002, albedo=0.02, radius_px=2.0)


def bark_texture(seed: int | np.random.Generator, shape: tuple[int, int] = (512, 128), *, low: float = 0.03,
                 high: float = 0.14) -> np.ndarray:
    """Bark: vertical fissures (long along the trunk = texture rows), dark albedo.

    Returns float32 (rows, cols, 3).
    """
    rng = as_rng(seed)
    fissures = fractal_noise(shape, rng, beta=1.8, stretch=(0.15, 1.0))
    grain = fractal_noise(shape, rng, beta=1.0)
    return albedo_map(0.7 * fissures + 0.3 * grain, low, high, (1.0, 0.85, 0.7))


def foliage_texture(seed: int | np.random.Generator, size: int = 256, *, low: float = 0.02, high: float = 0.09,
                    colour: tuple[float, float, float] = (0.55, 1.0, 0.5)) -> np.ndarray:
    """Needles or leaves seen from afar: blotchy dark green.

    Returns float32 (size, size, 3).
    """
    rng = as_rng(seed)
    blotch = fractal_noise((size, size), rng, beta=1.4)
    return albedo_map(blotch, low, high, colour, gamma=1.3)


def rock_texture(seed: int | np.random.Generator, size: int = 256) -> np.ndarray:
    """Lichen-covered granite: grey 0.08..0.35 with speckles.

    Returns float32 (size, size, 3).
    """
    rng = as_rng(seed)
    noise = 0.6 * fractal_noise((size, size), rng, beta=2.0) + 0.4 * fractal_noise((size, size), rng, beta=0.8)
    return albedo_map(noise, 0.08, 0.35, (1.0, 1.0, 0.95))


def chart_texture(
    seed: int | np.random.Generator,
    albedos: np.ndarray,
    *,
    patch_px: int = 64,
    gap_px: int = 8,
    gap_albedo: float = 0.3,
    modulation: float = 0.25,
) -> np.ndarray:
    """A patch chart: a grid of textured patches of given mean albedos.

    Parameters
    ----------
    seed : int or numpy.random.Generator
        Texture of every patch.
    albedos : numpy.ndarray
        (rows, cols) luminance albedo of each patch, in (0, 1].
    patch_px, gap_px : int
        Patch and gap sizes in texels.
    gap_albedo : float
        Albedo of the frame between patches.
    modulation : float
        Relative peak-to-peak texture contrast inside a patch (features for SIFT).

    Returns
    -------
    numpy.ndarray
        float32 (rows*(patch+gap)+gap, cols*(patch+gap)+gap, 3), neutral grey.
    """
    rng = as_rng(seed)
    albedos = np.asarray(albedos, dtype=np.float64)
    if albedos.ndim != 2 or np.any(albedos <= 0) or np.any(albedos > 1):
        raise SceneError("chart_texture: albedos must be a 2-D array of values in (0, 1]")
    rows, cols = albedos.shape
    step = patch_px + gap_px
    out = np.full((rows * step + gap_px, cols * step + gap_px), gap_albedo, dtype=np.float64)
    for r in range(rows):
        for c in range(cols):
            n = fractal_noise((patch_px, patch_px), rng, beta=1.6)
            y0, x0 = gap_px + r * step, gap_px + c * step
            factor = np.exp(modulation * (n - 0.5) * 2.0)
            out[y0:y0 + patch_px, x0:x0 + patch_px] = np.clip(albedos[r, c] * factor, 1e-4, 1.0)
    return np.repeat(out[..., None], 3, axis=-1).astype(np.float32)


# ------------------------------------------------------------------------------------------
# Detail layers: centimetre-scale structure that rides on the metre-scale albedo textures
# (see :class:`scenes.description.Material`, ``detail`` and ``bump``).  Values in [0, 1].
# ------------------------------------------------------------------------------------------

def specks(
    shape: tuple[int, int],
    seed: int | np.random.Generator,
    *,
    count: int,
    length_px: tuple[float, float],
    width_px: tuple[float, float],
    density=None,
    orientation: float | None = None,
) -> np.ndarray:
    """Coverage (0..1) of many small elongated specks: needles, twigs, grit, bark flakes.

    Each speck is an anisotropic Gaussian footprint (length and width are the
    full widths at about half coverage), composited by maximum, wrapped at the
    edges so the texture tiles.

    Parameters
    ----------
    shape : tuple of int
        (rows, columns).
    seed : int or numpy.random.Generator
        Positions, sizes and angles.
    count : int
        Number of specks.
    length_px, width_px : tuple of float
        Uniform ranges of speck length and width, texels (width <= length).
    density : numpy.ndarray, optional
        (rows, columns) non-negative weights: specks are placed with probability
        proportional to it (clustering), else uniformly.
    orientation : float, optional
        All specks along this angle (radians from the column axis), else random.

    Returns
    -------
    numpy.ndarray
        float32 ``shape``, coverage in [0, 1].
    """
    rng = as_rng(seed)
    rows, cols = (int(v) for v in shape)
    if count <= 0:
        return np.zeros((rows, cols), np.float32)
    if density is not None:
        p = np.asarray(density, dtype=np.float64).ravel()
        idx = rng.choice(p.size, size=int(count), p=p / p.sum())
        cy, cx = idx // cols, idx % cols
    else:
        cy, cx = rng.integers(0, rows, count), rng.integers(0, cols, count)
    length = rng.uniform(*length_px, count)
    width = np.minimum(rng.uniform(*width_px, count), length)
    angle = rng.uniform(0.0, np.pi, count) if orientation is None else np.full(count, float(orientation))
    half = int(np.ceil(max(length_px) / 2.0 + 1.5))
    yy, xx = (g.ravel() for g in np.mgrid[-half:half + 1, -half:half + 1])
    out = np.zeros(rows * cols)
    # in batches: (count, window) arrays stay small
    for start in range(0, count, 4096):
        sl = slice(start, start + 4096)
        c, s = np.cos(angle[sl])[:, None], np.sin(angle[sl])[:, None]
        u = xx[None, :] * c + yy[None, :] * s
        v = -xx[None, :] * s + yy[None, :] * c
        # FWHM -> sigma: divide by 2.355
        w = np.exp(-0.5 * ((u / (length[sl, None] / 2.355)) ** 2 + (v / (width[sl, None] / 2.355)) ** 2))
        index = ((cy[sl, None] + yy[None, :]) % rows) * cols + (cx[sl, None] + xx[None, :]) % cols
        np.maximum.at(out, index.ravel(), w.ravel())
    return np.clip(out, 0.0, 1.0).reshape(rows, cols).astype(np.float32)


def snow_detail(seed: int | np.random.Generator, size: int = 2048, *, tile_m: float = 3.0,
                needles_per_m2: float = 3000.0, twigs_per_m2: float = 120.0, debris_per_m2: float = 800.0,
                grain_contrast: float = 0.35, grain_beta: float = 2.0, grain_min_mm: float = 3.0,
                blobs_per_m2: float = 0.0, blob_mm: tuple[float, float] = (8.0, 64.0),
                blob_depth: float = 0.5) -> np.ndarray:
    """Centimetre-scale snow surface: grain and crust, and the litter a spruce stand drops on it.

    Spring snow under spruces carries hundreds of needles per square metre
    (1-2 cm long, about 1 mm wide), twigs, bark flakes and cone scales, in
    clusters; between them the crust has a scale-invariant (1/f^2 power) grain.
    Returns the detail weight for :class:`scenes.description.Material`: 1 on clean
    bright snow, towards 0 on litter (the material's ``detail_range`` maps it to an
    albedo factor).

    Parameters
    ----------
    size : int
        Texels per side; the tile covers ``tile_m`` metres (default 1.5 mm texels).
    needles_per_m2, twigs_per_m2, debris_per_m2 : float
        Litter densities (mean over the tile; clustered by a coarse noise).
    grain_contrast : float
        Peak-to-peak depth of the crust grain, as a fraction of the weight.
    grain_beta : float
        Spectral exponent of the grain (:func:`fractal_noise`).
    grain_min_mm : float
        Shortest wavelength of the grain, millimetres: structure much finer than a
        pixel's footprint averages out in the image, so the grain's contrast is put
        where the camera resolves it.
    blobs_per_m2 : float
        Density of 1 cm dimples, clumps and flakes; they come in octaves of size from
        ``blob_mm[0]`` to ``blob_mm[1]`` (each twice the last) with a density falling as
        the inverse square of the size, so every octave covers the same fraction of the
        surface: a self-similar pattern that gives blob-like features (what SIFT finds)
        at every image resolution, as natural ground cover does.
    blob_depth : float
        How much a blob darkens the weight (0..1).

    Returns
    -------
    numpy.ndarray
        float32 (size, size) in [0, 1].
    """
    rng = as_rng(seed)
    mm = tile_m * 1000.0 / size  # millimetres per texel
    area = tile_m * tile_m
    cluster = fractal_noise((size // 8, size // 8), rng, beta=2.2) ** 3
    cluster = np.kron(cluster, np.ones((8, 8), np.float32))
    grain = fractal_noise((size, size), rng, beta=grain_beta, min_wavelength_px=max(2.0, grain_min_mm / mm))
    needles = specks((size, size), rng, count=int(needles_per_m2 * area), length_px=(10 / mm, 20 / mm),
                     width_px=(1.2 / mm, 2.0 / mm), density=0.15 + cluster)
    twigs = specks((size, size), rng, count=int(twigs_per_m2 * area), length_px=(25 / mm, 45 / mm),
                   width_px=(2.5 / mm, 4.0 / mm), density=0.3 + cluster)
    debris = specks((size, size), rng, count=int(debris_per_m2 * area), length_px=(4 / mm, 9 / mm),
                    width_px=(3 / mm, 7 / mm), density=0.1 + cluster)
    litter = np.maximum(np.maximum(needles, twigs), 0.8 * debris)
    blobs = np.zeros((size, size), np.float32)
    octave_mm = float(blob_mm[0])
    while blobs_per_m2 > 0 and octave_mm <= blob_mm[1] * (1 + 1e-9):
        count = int(round(blobs_per_m2 * area * (10.0 / octave_mm) ** 2))
        depth = rng.uniform(0.3, 1.0, 1)[0]
        layer = specks((size, size), rng, count=count, length_px=(octave_mm / mm, 2.0 * octave_mm / mm),
                       width_px=(0.5 * octave_mm / mm, octave_mm / mm), density=0.3 + cluster)
        blobs = np.maximum(blobs, depth * layer)
        octave_mm *= 2.0
    w = (1.0 - grain_contrast * grain) * (1.0 - 0.92 * litter) * (1.0 - blob_depth * blobs)
    return np.clip(w, 0.0, 1.0).astype(np.float32)


def litter_detail(seed: int | np.random.Generator, size: int = 2048, *, tile_m: float = 3.0) -> np.ndarray:
    """Centimetre-scale forest floor: leaves, needles and twigs over soil, with gaps and shadows.

    Returns float32 (size, size) in [0, 1]: bright on leaf and needle tops, dark
    in the gaps between them.
    """
    rng = as_rng(seed)
    mm = tile_m * 1000.0 / size
    area = tile_m * tile_m
    base = fractal_noise((size, size), rng, beta=1.8)
    leaves = specks((size, size), rng, count=int(300 * area), length_px=(30 / mm, 70 / mm),
                    width_px=(15 / mm, 35 / mm))
    needles = specks((size, size), rng, count=int(3000 * area), length_px=(15 / mm, 40 / mm),
                     width_px=(1.5 / mm, 2.5 / mm))
    twigs = specks((size, size), rng, count=int(60 * area), length_px=(40 / mm, 90 / mm),
                   width_px=(3 / mm, 6 / mm))
    w = 0.25 + 0.45 * base
    w = np.maximum(w, 0.55 + 0.45 * leaves * base)
    w = np.maximum(w, 0.75 * needles)
    w = w * (1.0 - 0.7 * twigs) + 0.9 * twigs * (1 - base)
    return np.clip(w, 0.0, 1.0).astype(np.float32)


def needle_clumps(seed: int | np.random.Generator, size: int = 512, *, tile_m: float = 2.0,
                  clump_cm: float = 6.0, gap_fraction: float = 0.35) -> np.ndarray:
    """Spruce foliage at the scale of needle clumps: lit shoot tips, dark gaps into the crown.

    A scale-invariant field thresholded into clumps of about ``clump_cm`` with
    dark gaps covering ``gap_fraction``; inside the clumps, shoots (short
    streaks) vary the brightness.

    Returns float32 (size, size) in [0, 1]: 1 on lit shoot tips, 0 in the deepest gaps.
    """
    rng = as_rng(seed)
    mm = tile_m * 1000.0 / size
    field = fractal_noise((size, size), rng, beta=1.6, min_wavelength_px=max(2.0, clump_cm * 10 / mm / 4))
    shoots = specks((size, size), rng, count=int(400 * tile_m * tile_m), length_px=(40 / mm, 90 / mm),
                    width_px=(8 / mm, 15 / mm))
    clumps = np.clip((field - gap_fraction) / 0.25, 0.0, 1.0)
    w = clumps * (0.45 + 0.55 * shoots)
    return np.clip(w, 0.0, 1.0).astype(np.float32)


def bark_detail(seed: int | np.random.Generator, shape: tuple[int, int] = (512, 256)) -> np.ndarray:
    """Spruce bark at the centimetre scale: scaly plates separated by dark cracks.

    Returns float32 ``shape`` (rows along the trunk) in [0, 1].
    """
    rng = as_rng(seed)
    plates = fractal_noise(shape, rng, beta=1.6, stretch=(0.5, 1.0))
    cracks = specks(shape, rng, count=int(0.01 * shape[0] * shape[1]), length_px=(6.0, 14.0),
                    width_px=(1.0, 2.0), orientation=np.pi / 2)
    return np.clip((0.35 + 0.65 * plates) * (1.0 - 0.85 * cracks), 0.0, 1.0).astype(np.float32)


def relief(seed: int | np.random.Generator, size: int = 512, *, beta: float = 3.0,
           stretch: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """Height field for micro-relief (bump mapping): smooth fractal noise in [0, 1].

    ``beta`` 3 gives relief dominated by the larger bumps (trampled snow, wind
    crust) with finer ones on top.  Returns float32 (size, size).
    """
    rng = as_rng(seed)
    return fractal_noise((size, size), rng, beta=beta, stretch=stretch)
