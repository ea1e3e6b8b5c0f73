"""Capture: HDR radiance -> raw Bayer DN through a :class:`synth.Camera`, as a machine-vision camera does.

Model (DESIGN.md, "Synthetic camera"), per Bayer site ``(y, x)`` of colour ``c(y, x)``:

1. **Electrons** (mean), float64 on the noiseless path::

       e = radiance_scale * t_ms * V(y, x) * sum_j S[c, j] * E(y, x, j)

   ``E`` is the RGB radiance (W m^-2 sr^-1, float32 (H, W, 3)); a 2-D radiance (H, W)
   is already per site and is used as ``sum_j S[c, j] E_j`` (no sensitivity applied).
   ``S`` is :attr:`Camera.sensitivities` (rows: the R, G, B sites; columns: radiance
   R, G, B), ``V`` the vignetting (:meth:`Camera.vignetting_map`), ``t_ms`` the exposure.
2. **Noise** (``noise=True``): photon shot noise, Poisson in electrons, plus Gaussian read
   noise of ``read_noise_e`` electrons rms.  The sum is drawn as
   ``e + sqrt(e + read_noise_e**2) * z`` (the Gaussian approximation, exact mean and
   variance) wherever its skewness ``e / (e + read_noise_e**2)**1.5`` is at most
   :data:`SKEWNESS_LIMIT` (0.2, the skewness of a Poisson variable of 25 electrons);
   elsewhere the shot noise is an exact Poisson sample (``numpy.random.Generator.poisson``)
   plus ``read_noise_e * z``.  The skewness of the sum never exceeds
   ``0.385 / read_noise_e``, so a camera with 2 e- or more of read noise (every preset)
   is Gaussian throughout, and one with little read noise draws exact Poisson in the
   dark (below 25 e- with none): :meth:`Camera.exact_poisson_range_e`.  ``z`` comes from
   a 65536-level table of standard-normal quantiles indexed by 16 random bits
   (:data:`NORMAL_LEVELS`), rescaled to exactly zero mean and unit variance, so it is
   truncated at +-4.3 sigma (1.5e-5 of draws per side lie beyond).  The noisy path
   computes in float32; with the table this is what brings a noisy 1920x1200 frame under
   the camera's frame time (``benchmarks/bench_capture.py``).
3. **Linear exposure** for the response, proportional to electrons (so that an exposure
   ratio is exactly a ratio of h, as the emulator assumes)::

       h = e * g(white_level) / full_well_e

   i.e. the full well is the exposure that reaches ``white_level``.
4. **Quantisation and clipping**::

       DN = clip(floor(f(h) + 1/2), black_level, white_level)

   with ``f`` the piecewise-linear inverse of the response table g (what
   :meth:`emulator.core.response.CameraResponse.forward` evaluates).  ``floor(f(h) + 1/2)``
   is the number of decision levels ``g(d + 1/2) = (g[d] + g[d+1]) / 2`` at or below h
   (round half up; ties have probability zero).  The noiseless path evaluates this
   exactly (a lookup table with an exact fix-up near decision levels).  The noisy path
   first rounds the noisy electron count to a grid of ``2**16`` steps over the response
   range (about 0.16 e- for a 10500 e- well, negligible next to the read noise) and
   reads DN from a table of that grid.

With ``noise=False`` the result is the exact noiseless image of 1., 3. and 4., which
tests recompute independently.  The same seed gives the same bytes (for one numpy
version: numpy does not promise identical random streams across versions).

The black level is part of the response: a preset built with ``black_level=b`` has
g(b) = 0, so no light gives DN b (an offset), and DN at or below b count as clipped.

The camera's parameters, vignetting and mosaic weights are in :mod:`synth.camera`; the noise
sampler and the quantiser in :mod:`synth.sensor`; the presets in :mod:`synth.presets`.
"""

from __future__ import annotations

import numpy as np

from synth.camera import Camera, check_exposure_ms
from synth.errors import RadianceError, SynthError
from synth.sensor import noisy_grid_index, rng_of

__all__ = ["capture", "check_radiance", "mean_electrons"]

#: Electron means are capped at this many full wells before noise and quantisation: the
#: result is white either way (the truncated Gaussian moves a sample by < 4.4 sigma), and
#: the grid index stays far inside int32 (OpenCV's float -> int32 conversion does not
#: saturate).  The cap is skipped when the brightest radiance cannot reach it.
_ELECTRON_CAP_FULL_WELLS = 2.0
#: Rows per block of the noisy path (its float32 intermediates then stay in the CPU cache).
_BLOCK_ROWS = 32
#: Largest finite float32 / float64 bit patterns of a non-negative number (sign bit clear).
_FINITE_BITS = {np.dtype(np.float32): np.uint32(0x7F7FFFFF), np.dtype(np.float64): np.uint64(0x7FEFFFFFFFFFFFFF)}


def check_radiance(radiance, camera: Camera, name: str = "radiance") -> np.ndarray:
    """Validate a radiance image for ``camera``; return it unchanged.

    Accepts float32 or float64, shape (height, width, 3) RGB or (height, width) per site,
    every value finite and >= 0.  Raises :class:`RadianceError` naming the problem: for bad
    values, how many pixels and where the first one is (row, column).
    """
    _radiance_max(radiance, camera, name)
    return radiance


def _radiance_max(radiance, camera: Camera, name: str = "radiance") -> float:
    """:func:`check_radiance`, returning the largest value (one pass over the image)."""
    if not isinstance(radiance, np.ndarray):
        raise RadianceError(f"{name} must be a numpy array, got {type(radiance).__name__}")
    if radiance.dtype not in _FINITE_BITS:
        raise RadianceError(f"{name} must be float32 (or float64) linear radiance, got dtype {radiance.dtype}")
    want = (camera.height, camera.width)
    if radiance.shape not in (want, want + (3,)):
        raise RadianceError(
            f"{name} must have shape {want + (3,)} (RGB) or {want} (per site) for camera "
            f"{camera.name!r}, got {radiance.shape}"
        )
    # one pass: as unsigned integers, negative numbers (sign bit), inf and NaN all exceed
    # the largest finite positive bit pattern
    if radiance.flags.c_contiguous:
        bits = radiance.view(np.uint32 if radiance.dtype == np.float32 else np.uint64)
        top = np.max(bits)
        if top <= _FINITE_BITS[radiance.dtype]:
            return float(np.array(top).view(radiance.dtype))
    for what, bad in (
        ("NaN", np.isnan(radiance)),
        ("infinite", np.isinf(radiance)),
        ("negative", radiance < 0),
    ):
        per_pixel = bad.any(axis=2) if bad.ndim == 3 else bad
        n = int(np.count_nonzero(per_pixel))
        if n:
            r, c = np.unravel_index(int(np.argmax(per_pixel)), per_pixel.shape)
            raise RadianceError(
                f"{name} has {n} pixel(s) with {what} values; the first at row {r}, column {c} "
                f"(value {radiance[r, c].tolist()})"
            )
    return float(np.max(radiance))  # -0.0, or a non-contiguous array with valid values


def mean_electrons(radiance: np.ndarray, exposure_ms: float, camera: Camera, dtype=np.float64) -> np.ndarray:
    """Mean electrons per Bayer site (no noise, no clipping), ``dtype`` (H, W).

    ``radiance_scale * V * S[c, j] * E_j * t`` summed over j (module docstring, step 1);
    ``radiance`` is not validated here (see :func:`check_radiance`).
    """
    dtype = np.dtype(dtype)
    if dtype == np.float32:
        return _electrons_f32(radiance, camera, slice(None), float(exposure_ms))
    flat = np.ascontiguousarray(radiance).reshape(-1)
    out = None
    for idx, w in camera._mosaic_terms(dtype, radiance.ndim == 3):
        term = np.multiply(radiance if idx is None else np.take(flat, idx), w, dtype=dtype)
        term *= exposure_ms
        out = term if out is None else np.add(out, term, out=out)
    return out


def _electrons_f32(radiance: np.ndarray, camera: Camera, rows: slice, exposure_ms: float) -> np.ndarray:
    """:func:`mean_electrons` in float32 for a block of rows (one pass per term through OpenCV)."""
    import cv2

    flat = np.ascontiguousarray(radiance).reshape(-1)
    out = None
    for idx, w in camera._mosaic_terms(np.float32, radiance.ndim == 3):
        src = radiance[rows] if idx is None else np.take(flat, idx[rows])
        term = cv2.multiply(src.astype(np.float32, copy=False), w[rows], scale=exposure_ms)
        out = term if out is None else cv2.add(out, term, out)
    return out


def capture(radiance, exposure_ms, camera: Camera, *, seed, noise: bool = True) -> np.ndarray:
    """Capture one raw image of ``radiance`` at ``exposure_ms`` through ``camera``.

    Parameters
    ----------
    radiance : ndarray, float32 (H, W, 3) RGB or (H, W) per site
        Linear scene radiance, W m^-2 sr^-1, finite and >= 0; (H, W) is the camera's.
    exposure_ms : float
        Exposure time, milliseconds, finite and > 0.
    camera : Camera
        The camera (response, levels, noise figures, vignetting, mosaic).
    seed : int, numpy.random.SeedSequence or numpy.random.Generator
        Source of the noise; the same seed gives the same bytes.  Ignored (and may be
        None) when ``noise`` is False.
    noise : bool
        False gives the exact noiseless image (float64 electrons, no random draw).

    Returns
    -------
    ndarray, uint16 (H, W)
        Bayer mosaic in DN, ``black_level <= DN <= white_level`` (module docstring).

    Raises
    ------
    RadianceError
        Wrong type, dtype or shape, or NaN / infinite / negative values (with the count
        and the first pixel).
    SynthError
        Non-positive exposure or an invalid seed.
    """
    if not isinstance(camera, Camera):
        raise SynthError(f"camera must be a synth.Camera, got {type(camera).__name__}")
    t = check_exposure_ms(exposure_ms)
    peak = _radiance_max(radiance, camera)
    cap = _ELECTRON_CAP_FULL_WELLS * camera.full_well_e
    q = camera._quantiser()
    if not noise:
        e = mean_electrons(radiance, t, camera, np.float64)
        np.minimum(e, cap, out=e)
        return q.exact(e)
    if seed is None:
        raise SynthError("seed is required for a noisy capture (pass noise=False for the noiseless image)")
    rng = rng_of(seed)
    import cv2

    out = np.empty((camera.height, camera.width), dtype=np.uint16)
    radiance = np.ascontiguousarray(radiance, dtype=np.float32)
    clip = peak * camera._max_site_weight(radiance.ndim == 3) * t > cap  # else min() changes nothing
    for start in range(0, camera.height, _BLOCK_ROWS):  # blocks keep the intermediates in cache
        rows = slice(start, start + _BLOCK_ROWS)
        e = _electrons_f32(radiance, camera, rows, t)
        if clip:
            cv2.min(e, cap, e)
        out[rows] = q.grid(noisy_grid_index(e, camera, q, rng))
    return out
