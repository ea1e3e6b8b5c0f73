"""What blur-consistent emulation moves: the structure of a plane, told from its noise.

:func:`structure_of` is the ``s`` of :func:`emulator.core.blur.emulate_blur_consistent`
(``h_T = (T/S) h_S + sum_j (w_j/S) (warp_j(s) - s)``): the scene's structure moves with the
camera, the source's noise stays where it is, as a live capture's noise is never smeared.
Measurements behind the choices: docs/blur.md, section "Blur-consistent emulation".
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from emulator.errors import EmulationError

__all__ = ["structure_of", "STRUCTURE_SIGMA_PX", "STRUCTURE_FILTERS"]

#: Window (Gaussian sigma, px of one Bayer plane) of the structure the blur moves (see
#: :func:`structure_of`): the source's own noise is not smeared.
STRUCTURE_SIGMA_PX = 1.0
#: How the structure the blur moves is told from the noise it must not smear (:func:`structure_of`).
STRUCTURE_FILTERS = ("wiener", "gaussian")
_NOISE_BINS = 16
#: The Wiener filter subtracts this many times the measured noise variance.  Chosen on the BorealHDR
#: sample at rest: with 3, --blur consistent changes every emulated image by less than 0.92 of its own
#: noise even at the synth preset's 10 500 e- (0.40 at the in-situ 2005 e-); with 2 it was 1.05
#: (scripts/blur_sample_checks.py rest, docs/blur.md).
_WIENER_OVERSUBTRACT = 3.0


def _gaussian_weights(sigma: float) -> np.ndarray:
    k = cv2.getGaussianKernel(2 * int(math.ceil(4.0 * sigma)) + 1, sigma)
    return (k @ k.T).astype(np.float64)


def structure_of(plane: np.ndarray, sigma_px: float | None = None, method: str = "wiener",
                 noise_var=None, exclude: np.ndarray | None = None) -> np.ndarray:
    """The structure of one (Bayer) plane in linear exposure: what blur moves, without the noise.

    ``"gaussian"``: the plane smoothed by a Gaussian of ``sigma_px``; it drops fine structure with
    the noise.  ``"wiener"`` (an adaptive Wiener filter, Lee 1980): ``mu + k (x - mu)`` with ``mu``
    and ``v`` the local mean and variance over that Gaussian window and
    ``k = max(0, 1 - 3 c n / v)``, ``n`` the noise variance at the level ``mu`` and
    ``c = 1 - sum w^2`` (about 0.92: the share of white noise's variance that a local variance
    over the window ``w`` sees).  Three times the noise: flat noisy regions become ``mu``, so
    their noise is not moved, while edges and texture well above the noise stay and are moved.

    ``noise_var``: ``n`` in the plane's units, a number or a function of ``mu``; None measures it
    on the plane itself: in 16 bins of ``mu``, the robust (MAD) variance of the finest diagonal
    Haar detail (:func:`_plane_noise_var`), leaving out the blocks ``exclude`` (a boolean mask of
    the plane, e.g. its clipped pixels, whose zero detail is not a noise level).  Texture at the
    pixel scale raises that measure, so on a noiseless plane give ``noise_var=0`` (the plane is
    returned as it is).  Integer planes are taken as float32.
    """
    sigma_px = STRUCTURE_SIGMA_PX if sigma_px is None else float(sigma_px)
    given = None  # a noise variance given as a number
    if noise_var is not None and not callable(noise_var):
        given = float(noise_var)
        if not (math.isfinite(given) and given >= 0):
            raise EmulationError(f"noise_var must be a finite variance >= 0, got {noise_var!r}")
    if not np.issubdtype(plane.dtype, np.floating):
        plane = plane.astype(np.float32)
    if method not in STRUCTURE_FILTERS:
        raise EmulationError(f"structure must be one of {', '.join(STRUCTURE_FILTERS)}, got {method!r}")
    if sigma_px <= 0 or (method == "wiener" and given == 0.0):
        return plane
    mu = cv2.GaussianBlur(plane, (0, 0), sigma_px, borderType=cv2.BORDER_REPLICATE)
    if method == "gaussian":
        return mu
    var_gain = 1.0 - float(np.sum(_gaussian_weights(sigma_px) ** 2))  # E[local variance] / var(x), white noise
    resid = plane - mu
    if given is not None:
        n = np.float32(given)
    elif callable(noise_var):
        n = np.asarray(noise_var(mu), dtype=np.float32)
    else:
        n = _plane_noise_var(plane, mu, exclude)
    var = np.maximum(cv2.GaussianBlur(plane * plane, (0, 0), sigma_px, borderType=cv2.BORDER_REPLICATE) - mu * mu, 0)
    k = np.clip(1.0 - _WIENER_OVERSUBTRACT * var_gain * n / np.maximum(var, 1e-30), 0.0, 1.0)
    return (mu + k * resid).astype(plane.dtype, copy=False)


def _plane_noise_var(plane: np.ndarray, mu: np.ndarray, exclude: np.ndarray | None = None) -> np.ndarray:
    """Noise variance per pixel: the MAD of the finest diagonal Haar detail of each 2x2 block
    ``(x[i,j] - x[i,j+1] - x[i+1,j] + x[i+1,j+1]) / 2`` (variance = the noise's for white noise; zero on
    any plane linear in x and y, so smooth shading does not count) in 16 bins of the local mean."""
    h2, w2 = (plane.shape[0] // 2) * 2, (plane.shape[1] // 2) * 2
    x = plane[:h2, :w2]
    d = 0.5 * np.abs(x[0::2, 0::2] - x[0::2, 1::2] - x[1::2, 0::2] + x[1::2, 1::2]).ravel()
    level = mu[:h2:2, :w2:2].ravel()
    if exclude is not None:
        e = np.asarray(exclude, dtype=bool)[:h2, :w2]
        keep = ~(e[0::2, 0::2] | e[0::2, 1::2] | e[1::2, 0::2] | e[1::2, 1::2]).ravel()
        d, level = d[keep], level[keep]
    if d.size < 16:
        return np.zeros_like(mu)
    order = np.argsort(level, kind="stable")  # 16 bins of equal count
    centres, noise = [], []
    for part in np.array_split(order, min(_NOISE_BINS, d.size // 16)):
        centres.append(float(np.median(level[part])))
        noise.append((1.4826 * float(np.median(d[part]))) ** 2)
    xs, inv = np.unique(centres, return_inverse=True)  # bins of one level (a clipped plane): one point
    ys = np.bincount(inv, weights=noise) / np.bincount(inv)
    return np.interp(mu, xs, ys).astype(np.float32)
