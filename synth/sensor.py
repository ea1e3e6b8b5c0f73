"""The sensor's noise and quantisation: steps 2 and 4 of the model in :mod:`synth.imaging`.

* :func:`noisy_grid_index`: shot + read noise of float32 mean electrons (Gaussian
  approximation from a 65536-level quantile table, exact Poisson where the sum is skewed),
  as an index on the quantiser's electron grid;
* :class:`Quantiser`: electrons -> DN through the camera's inverse response, exactly on
  the noiseless path and from a grid table on the noisy one;
* :func:`noise_model_g`: the temporal noise of h that this model implies.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from synth.errors import SynthError

if TYPE_CHECKING:  # only for annotations: synth.camera imports this module
    from synth.camera import Camera

__all__ = [
    "SKEWNESS_LIMIT",
    "NORMAL_LEVELS",
    "Quantiser",
    "noisy_grid_index",
    "noise_model_g",
    "rng_of",
    "skewed_range",
]

#: Shot + read noise is drawn from the Gaussian approximation where its skewness
#: ``e / (e + read_noise_e**2)**1.5`` is at most this; exact Poisson elsewhere.
SKEWNESS_LIMIT = 0.2
#: Number of quantile levels of the fast standard-normal sampler (16 random bits).
NORMAL_LEVELS = 1 << 16
#: Steps of the electron grid of the quantiser's lookup tables over the response range.
_QUANTISER_BINS = 1 << 16
#: Bins within this margin (in bins) of a decision level are resolved exactly on the
#: noiseless path (float rounding of the bin index is far below it).
_QUANTISER_MARGIN_BINS = 0.25
#: Flag bit of a lookup-table bin with a decision level within the margin.
_AMBIGUOUS = np.uint16(0x8000)


class Quantiser:
    """Electrons -> DN: ``black + #{decision levels <= e}``, clipped to [black, white].

    Decision levels in electrons: ``theta_d = (g[d] + g[d + 1]) / 2 / h_per_electron`` for
    d = black .. white - 1.  A uniform grid over the levels' range, ``e_k = (k - offset) /
    scale`` for k = 0 .. bins + 1 (the first and last grid points lie beyond every level),
    carries two tables:

    * ``grid_lut[k]``: DN of the grid point e_k (the noisy path rounds to the grid);
    * ``lut[k]``: DN of the whole bin ``[e_k, e_k+1)``, flagged where a level lies within
      a margin of it; ``single[k]`` is that level when it is alone.  The exact path reads
      unflagged bins from the table, compares with the one level of singly flagged bins
      and searches all levels in the rest, which makes it exact.
    """

    def __init__(self, camera: "Camera") -> None:
        g = camera.response.g
        black, white = camera.black_level, camera.white_level
        theta = 0.5 * (g[black:white] + g[black + 1: white + 1]) / camera.h_per_electron
        self.theta = theta
        self.black = black
        n = _QUANTISER_BINS
        span = max(theta[-1] - theta[0], 1e-9 * max(abs(theta[0]), 1.0))
        width = span / (n - 8)
        first = theta[0] - 5.0 * width  # e_0; e_1 = theta_0 - 4 width, e_(n+1) = theta_last + 4 width
        self.scale = 1.0 / width
        self.offset = -first * self.scale
        points = first + width * np.arange(n + 2, dtype=np.float64)
        self.grid_lut = (black + np.searchsorted(theta, points, side="right")).astype(np.uint16)
        margin = _QUANTISER_MARGIN_BINS * width
        left, right = points.copy(), points + width
        left[0], right[-1] = -np.inf, np.inf
        count_lo = np.searchsorted(theta, left - margin, side="right")
        inside = np.searchsorted(theta, right + margin, side="left") - count_lo
        lut = (black + count_lo).astype(np.uint16)
        lut[inside > 0] |= _AMBIGUOUS
        single = np.full(n + 2, np.nan)
        one = inside == 1
        single[one] = theta[count_lo[one]]
        self.lut, self.single = lut, single

    def exact(self, e: np.ndarray) -> np.ndarray:
        """DN (uint16, same shape) of finite electron counts ``e``, exactly."""
        idx = np.multiply(e, self.scale)
        idx += self.offset
        np.clip(idx, -1.0, self.lut.size, out=idx)
        idx = idx.astype(np.intp)
        dn = np.take(self.lut, idx, mode="clip")
        flat = dn.reshape(-1)
        amb = np.flatnonzero(flat & _AMBIGUOUS)
        if amb.size:
            bins = np.clip(idx.reshape(-1)[amb], 0, self.lut.size - 1)
            ev = e.reshape(-1)[amb].astype(np.float64)
            th = self.single[bins]
            fixed = (self.lut[bins] & ~_AMBIGUOUS).astype(np.int64) + (ev >= th)
            multi = np.isnan(th)
            if multi.any():
                fixed[multi] = self.black + np.searchsorted(self.theta, ev[multi], side="right")
            flat[amb] = fixed
        return dn

    def grid(self, index: np.ndarray) -> np.ndarray:
        """DN (uint16) of grid indices ``round(e * scale + offset)`` (int32; out of range clips)."""
        return np.take(self.grid_lut, index, mode="clip")


def skewed_range(read_var: float, limit: float) -> list[float] | None:
    """Where ``x / (x + read_var)**1.5 > limit`` for x > 0, as [lo, hi]; None if nowhere."""
    from scipy.optimize import brentq

    if read_var == 0.0:
        return [0.0, 1.0 / limit**2]
    peak = 2.0 * read_var  # the skewness peaks there at 2 / (3**1.5 * sqrt(read_var))
    skew = lambda x: x / (x + read_var) ** 1.5 - limit  # noqa: E731
    if skew(peak) <= 0.0:
        return None
    lo = brentq(skew, 0.0, peak, xtol=1e-12)
    hi = brentq(skew, peak, 1.0 / limit**2 + peak, xtol=1e-9)
    return [float(lo), float(hi)]


def _normal_table() -> np.ndarray:
    from scipy.special import ndtri

    global _NORMAL_TABLE
    if _NORMAL_TABLE is None:
        q = ndtri((np.arange(NORMAL_LEVELS, dtype=np.float64) + 0.5) / NORMAL_LEVELS)
        q -= q.mean()
        q /= np.sqrt(np.mean(q * q))
        _NORMAL_TABLE = q.astype(np.float32)
        _NORMAL_TABLE.setflags(write=False)
    return _NORMAL_TABLE


_NORMAL_TABLE: np.ndarray | None = None


def rng_of(seed) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, np.random.SeedSequence):
        return np.random.default_rng(seed)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SynthError(
            f"seed must be a non-negative integer, a numpy SeedSequence or Generator, got {seed!r}"
        )
    return np.random.default_rng(int(seed))


def noisy_grid_index(e: np.ndarray, camera: "Camera", q: Quantiser, rng: np.random.Generator) -> np.ndarray:
    """Grid index (int32) of the noisy electron count of each site, from float32 means ``e``."""
    import cv2

    # 16 uniform random bits per site: four per raw 64-bit output of the bit generator
    bits = rng.bit_generator.random_raw(-(-e.size // 4)).view(np.uint16)[: e.size].reshape(e.shape)
    z = np.take(_normal_table(), bits)
    read_var = camera.read_noise_e**2
    noise = cv2.add(e, read_var)
    cv2.sqrt(noise, noise)
    cv2.multiply(noise, z, noise, scale=q.scale)  # noise in grid steps
    index = cv2.addWeighted(e, q.scale, noise, 1.0, q.offset, dtype=cv2.CV_32S)
    window = camera.exact_poisson_range_e()
    if window is not None:
        flat = e.reshape(-1)
        where = np.flatnonzero((flat > window[0]) & (flat < window[1]))
        if where.size:
            shot = rng.poisson(flat[where]) + camera.read_noise_e * z.reshape(-1)[where]
            index.reshape(-1)[where] = np.rint(shot * q.scale + q.offset).clip(-1, q.grid_lut.size)
    return index



def noise_model_g(camera: "Camera") -> tuple[float, float]:
    """Temporal noise of h (units of g): ``var(h) = shot * h + floor``.

    Returns ``(shot, floor)`` with ``shot = h_per_electron`` (g of one electron) and
    ``floor = (read_noise_e * h_per_electron)^2``; quantisation not included.
    """
    k = camera.h_per_electron
    return k, (camera.read_noise_e * k) ** 2
