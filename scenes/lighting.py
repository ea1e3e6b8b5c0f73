"""Daylight: sun colour and direction, and the sky as an environment map.

Colours come from colour-science (CIE daylight locus -> XYZ -> linear Rec.709),
never from hand-typed RGB triples.  colour-science is imported inside
:func:`daylight_rgb` (about one second) and the result is cached per CCT.

Units: radiance and irradiance in W m^-2 sr^-1 and W m^-2 with the RGB triple
normalised to Rec.709 luminance, so a white Lambertian surface facing a sun of
irradiance E has luminance E / pi.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from scenes.errors import SceneError

__all__ = [
    "LUMINANCE_WEIGHTS_REC709",
    "SUN_ANGULAR_DIAMETER_DEG",
    "daylight_rgb",
    "sun_direction",
    "sky_envmap",
    "envmap_direction",
    "ENVMAP_TO_WORLD",
]

#: Rec.709 / sRGB luminance weights (the Y row of the RGB -> XYZ matrix, D65).
#: ``tests/scenes/test_scenes.py`` checks them against colour-science.
LUMINANCE_WEIGHTS_REC709 = (0.2126, 0.7152, 0.0722)

#: Apparent diameter of the sun seen from the earth, degrees.
SUN_ANGULAR_DIAMETER_DEG = 0.533


@functools.lru_cache(maxsize=32)
def _daylight_rgb_cached(cct_k: float) -> tuple[float, float, float]:
    import colour  # ~1 s; only when a scene is built

    # CCT_to_xy_CIE_D expects the CCT on the 1931 c2 scale of the CIE D series;
    # rescale by 1.4388 / 1.4380 as the CIE 015 recommends.
    xy = colour.temperature.CCT_to_xy_CIE_D(cct_k * 1.4388 / 1.4380)
    xyz = colour.xy_to_XYZ(xy)
    space = colour.RGB_COLOURSPACES["ITU-R BT.709"]
    rgb = np.asarray(space.matrix_XYZ_to_RGB, dtype=np.float64) @ np.asarray(xyz, dtype=np.float64)
    rgb = np.clip(rgb, 0.0, None)
    rgb = rgb / float(np.dot(rgb, LUMINANCE_WEIGHTS_REC709))
    return tuple(float(v) for v in rgb)


def daylight_rgb(cct_k: float) -> np.ndarray:
    """Linear Rec.709 RGB of CIE daylight at a correlated colour temperature.

    Parameters
    ----------
    cct_k : float
        Correlated colour temperature in kelvin, 4000..25000 (the CIE D series
        range): ~4500 K for a low sun, 5500 K for midday sun, 10000+ K for blue sky.

    Returns
    -------
    numpy.ndarray
        float64, shape (3,), linear RGB (Rec.709 primaries, no white balance:
        D65 maps to (1, 1, 1)) scaled to luminance 1.

    Notes
    -----
    The chromaticity is the CIE daylight locus (CIE 015:2018, eq. 4.7-4.8),
    converted XYZ -> RGB without chromatic adaptation, so a low sun is warm and
    the sky blue relative to D65.
    """
    cct = float(cct_k)
    if not math.isfinite(cct) or not 4000.0 <= cct <= 25000.0:
        raise SceneError(f"cct_k must be in 4000..25000 K (CIE daylight), got {cct_k!r}")
    return np.array(_daylight_rgb_cached(round(cct, 6)), dtype=np.float64)


def sun_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """Unit vector from the scene towards the sun, world frame (z up).

    Parameters
    ----------
    elevation_deg : float
        Angle above the horizon, degrees, in (0, 90].
    azimuth_deg : float
        Angle in the ground plane from +x towards +y, degrees.

    Returns
    -------
    numpy.ndarray
        float64, shape (3,).
    """
    if not 0.0 < float(elevation_deg) <= 90.0:
        raise SceneError(f"sun elevation_deg must be in (0, 90], got {elevation_deg!r}")
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


def envmap_direction(height: int, width: int) -> np.ndarray:
    """World direction of every texel centre of a Mitsuba ``envmap`` bitmap.

    Mitsuba's envmap is a latitude-longitude map with +y up in its local frame:
    ``u = atan2(d.x, -d.z) / 2pi``, ``v = acos(d.y) / pi``.  The scene rotates it
    with ``ENVMAP_TO_WORLD`` (local y -> world z, local z -> world -y), so a
    texel (v, u) looks along world ``(sin(theta) sin(phi), sin(theta) cos(phi),
    cos(theta))`` with ``theta = pi v`` and ``phi = 2 pi u``.

    Returns
    -------
    numpy.ndarray
        float64, (height, width, 3) unit vectors.
    """
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    theta = np.pi * v[:, None]
    phi = 2.0 * np.pi * u[None, :]
    return np.stack(
        np.broadcast_arrays(np.sin(theta) * np.sin(phi), np.sin(theta) * np.cos(phi), np.cos(theta)), axis=-1
    )


#: 4x4 rotation applied to the envmap: local +y (Mitsuba's envmap up) -> world +z.
ENVMAP_TO_WORLD = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)


def sky_envmap(
    *,
    horizontal_irradiance: float,
    sky_rgb: np.ndarray,
    sun_dir: np.ndarray,
    horizon_ratio: float = 2.0,
    circumsolar: float = 4.0,
    circumsolar_width_deg: float = 12.0,
    ground_radiance_ratio: float = 0.3,
    height: int = 128,
    width: int = 256,
) -> np.ndarray:
    """A smooth clear-sky environment map scaled to a given diffuse irradiance.

    The relative radiance is ``(1 + (horizon_ratio - 1) * (theta / 90deg)**2)
    * (1 + circumsolar * exp(-gamma / width))`` above the horizon (theta: zenith
    angle, gamma: angle to the sun); below the horizon it is constant at
    ``ground_radiance_ratio`` times the horizon value (mostly hidden by the
    ground plane).  The whole map is then scaled so that the irradiance it puts
    on an unoccluded horizontal surface is ``horizontal_irradiance``.

    Parameters
    ----------
    horizontal_irradiance : float
        Diffuse sky irradiance on a horizontal plane, W m^-2 (clear sky: about
        10-15 % of the direct normal sun irradiance).
    sky_rgb : numpy.ndarray
        (3,) colour of the sky, luminance 1 (see :func:`daylight_rgb`).
    sun_dir : numpy.ndarray
        (3,) unit vector towards the sun, world frame.
    horizon_ratio, circumsolar, circumsolar_width_deg, ground_radiance_ratio : float
        Shape of the radiance distribution (see above).
    height, width : int
        Envmap resolution (width = 2 * height).

    Returns
    -------
    numpy.ndarray
        float32 (height, width, 3) radiance, W m^-2 sr^-1, for Mitsuba's envmap
        with ``to_world = ENVMAP_TO_WORLD``.
    """
    d = envmap_direction(height, width)
    cos_theta = d[..., 2]
    theta = np.arccos(np.clip(cos_theta, -1.0, 1.0))
    gamma = np.arccos(np.clip(d @ np.asarray(sun_dir, dtype=np.float64), -1.0, 1.0))
    upper = (1.0 + (horizon_ratio - 1.0) * np.minimum(theta / (np.pi / 2), 1.0) ** 2) * (
        1.0 + circumsolar * np.exp(-gamma / math.radians(circumsolar_width_deg))
    )
    rel = np.where(cos_theta > 0.0, upper, ground_radiance_ratio * horizon_ratio)
    # irradiance on a horizontal plane: sum L cos(theta) dOmega over the upper half
    v = (np.arange(height) + 0.5) / height
    d_omega = (np.pi / height) * (2.0 * np.pi / width) * np.sin(np.pi * v)[:, None]
    e_rel = float(np.sum(np.where(cos_theta > 0.0, rel * cos_theta, 0.0) * d_omega))
    radiance = rel * (horizontal_irradiance / e_rel)
    return (radiance[..., None] * np.asarray(sky_rgb, dtype=np.float64)).astype(np.float32)
