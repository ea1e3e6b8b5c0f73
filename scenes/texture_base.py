"""The primitives the procedural textures of :mod:`scenes.textures` are made of (numpy, no Mitsuba).

:func:`fractal_noise`: periodic spectral (1/f^beta) noise synthesised with an FFT, so it tiles
without seams; :func:`albedo_map`: values mapped to albedos on a logarithmic ramp (natural
reflectance varies multiplicatively); :func:`sprinkle`: small dark specks scattered over a texture.
Every one is a deterministic function of its arguments and a seed (:func:`as_rng`).
"""

from __future__ import annotations

import numpy as np

from scenes.errors import SceneError

__all__ = ["as_rng", "fractal_noise", "albedo_map", "sprinkle"]


def as_rng(seed: int | np.random.Generator) -> np.random.Generator:
    """``seed`` itself when it is a generator, else a new generator seeded with it."""
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def fractal_noise(
    shape: tuple[int, int],
    seed: int | np.random.Generator,
    *,
    beta: float = 2.0,
    stretch: tuple[float, float] = (1.0, 1.0),
    min_wavelength_px: float = 2.0,
) -> np.ndarray:
    """Periodic fractal noise, ranked to a uniform distribution on [0, 1].

    Parameters
    ----------
    shape : tuple of int
        (rows, columns) of the texture, each >= 4.
    seed : int or numpy.random.Generator
        Source of the white noise.
    beta : float
        Spectral exponent: the power spectrum falls as ``1 / f**beta``
        (2 gives brown-ish, natural-looking noise; 1 is rougher).
    stretch : tuple of float
        Anisotropy (rows, columns): a factor > 1 stretches the features along
        that axis (bark fissures are long along the trunk).
    min_wavelength_px : float
        Frequencies with a wavelength shorter than this are removed (anti-aliasing
        of the texture itself).

    Returns
    -------
    numpy.ndarray
        float32, shape ``shape``, values in (0, 1), close to uniformly
        distributed (Gaussian field through an approximate normal CDF, so the
        histogram does not depend on ``beta``).
    """
    rows, cols = (int(s) for s in shape)
    if rows < 4 or cols < 4:
        raise SceneError(f"fractal_noise: shape must be at least 4x4, got {shape!r}")
    rng = as_rng(seed)
    white = rng.standard_normal((rows, cols))
    fy = np.fft.fftfreq(rows)[:, None] * stretch[0]
    fx = np.fft.rfftfreq(cols)[None, :] * stretch[1]
    f = np.hypot(fy, fx)
    f[0, 0] = 1.0
    amplitude = f ** (-beta / 2.0)
    amplitude[0, 0] = 0.0
    amplitude[f > 1.0 / min_wavelength_px] = 0.0
    field = np.fft.irfft2(np.fft.rfft2(white) * amplitude, s=(rows, cols))
    field = (field - field.mean()) / max(float(field.std()), 1e-300)
    # The field is a linear filter of Gaussian white noise, hence Gaussian: its
    # normal CDF is uniform on [0, 1].  The logistic approximation
    # 1 / (1 + exp(-1.702 x)) is within 0.01 of the CDF and needs no scipy.
    return (1.0 / (1.0 + np.exp(-1.702 * field))).astype(np.float32)


def albedo_map(
    noise: np.ndarray, low: float, high: float, colour: tuple[float, float, float], *, gamma: float = 1.0
) -> np.ndarray:
    """Map noise in [0, 1] to an RGB albedo texture with a logarithmic ramp.

    Parameters
    ----------
    noise : numpy.ndarray
        (H, W) values in [0, 1].
    low, high : float
        Albedo (luminance) at noise 0 and 1, 0 < low <= high <= 1.
    colour : tuple of float
        Relative RGB tint; it is normalised to Rec.709 luminance 1.
    gamma : float
        Exponent applied to the noise before the ramp (> 1 favours dark values).

    Returns
    -------
    numpy.ndarray
        float32, (H, W, 3), linear RGB albedo in (0, 1].
    """
    if not 0.0 < low <= high <= 1.0:
        raise SceneError(f"albedo_map: need 0 < low <= high <= 1, got low={low}, high={high}")
    tint = np.asarray(colour, dtype=np.float64)
    tint = tint / float(np.dot(tint, (0.2126, 0.7152, 0.0722)))
    y = low * (high / low) ** (np.asarray(noise, dtype=np.float64) ** gamma)
    rgb = y[..., None] * tint
    return np.clip(rgb, 1e-4, 1.0).astype(np.float32)


def sprinkle(
    texture: np.ndarray, seed: int | np.random.Generator, *, density: float, albedo: float, radius_px: float = 1.5
) -> np.ndarray:
    """Scatter small dark specks (needles, twigs, grit) over a texture.

    Parameters
    ----------
    texture : numpy.ndarray
        float32 (H, W, 3) albedo; not modified.
    seed : int or numpy.random.Generator
        Positions and sizes of the specks.
    density : float
        Specks per texel (e.g. 0.002).
    albedo : float
        Luminance albedo of a speck.
    radius_px : float
        Mean speck radius in texels.

    Returns
    -------
    numpy.ndarray
        float32 (H, W, 3), a copy with the specks blended in (periodic wrap).
    """
    rng = as_rng(seed)
    rows, cols = texture.shape[:2]
    count = int(round(density * rows * cols))
    cy = rng.integers(0, rows, count)[:, None]
    cx = rng.integers(0, cols, count)[:, None]
    r = (radius_px * rng.uniform(0.5, 1.5, count))[:, None]
    a = rng.uniform(0.0, np.pi, count)[:, None]
    yy, xx = (g.ravel()[None, :] for g in np.mgrid[-4:5, -4:5])
    # elongated specks (needles): anisotropic gaussian footprints, wrapped at the edges
    u = xx * np.cos(a) + yy * np.sin(a)
    v = -xx * np.sin(a) + yy * np.cos(a)
    w = np.exp(-0.5 * ((u / (2.0 * r)) ** 2 + (v / (0.6 * r)) ** 2))
    index = ((cy + yy) % rows) * cols + (cx + xx) % cols
    weight = np.zeros(rows * cols)
    np.maximum.at(weight, index.ravel(), w.ravel())
    weight = weight.reshape(rows, cols, 1)
    out = texture.astype(np.float64) * (1.0 - weight) + albedo * weight
    return out.astype(np.float32)
