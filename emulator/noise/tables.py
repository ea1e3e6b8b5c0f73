"""Noise-consistent emulation: per-ratio noise tables, the exact quantiser, the noise kernel.

:class:`NoiseTables` holds, per source DN and Bayer phase, the variance of a live capture
at the target exposure and of the plain emulation, and what consistent emulation adds
(:meth:`emulator.noise.NoiseModel.tables` builds and caches them);
:func:`consistent_noise` adds the missing noise to a plain emulation and
:func:`excess_map` gives the per-pixel variance ratio.  Random draws:
:func:`standard_normal` (a quantile table indexed by 16 random bits) from a generator
that :func:`check_rng` demands explicitly.
"""

from __future__ import annotations

import math
import statistics
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import cv2
import numpy as np

from emulator.errors import EmulationError
from emulator.core.response import CameraResponse
from emulator.pools import lut_pool

if TYPE_CHECKING:
    from emulator.noise.model import NoiseModel

__all__ = ["NoiseTables", "check_rng", "standard_normal", "quantise", "consistent_noise", "excess_map",
           "NORMAL_LEVELS", "QUANTISER_BINS", "response_slope", "build_tables"]

#: Quantile levels of the fast standard-normal sampler (16 random bits per draw).
NORMAL_LEVELS = 1 << 16
#: Bins of the quantiser's grid (uniform in sqrt(h - h0), indexed by uint16 for ``cv2.LUT``):
#: the responses of this project have at most one decision level in all but a handful of
#: bins (3 for the BorealHDR pcalib table, none for the synth presets); bins with more
#: are resolved exactly by a binary search.
QUANTISER_BINS = 1 << 16
#: Decision levels within this many bins of a bin's edges are compared explicitly.
_QUANTISER_MARGIN_BINS = 0.25
_MULTI = np.uint16(0x8000)
#: Pixels per block of the noise kernel (its float32 temporaries then stay in the CPU cache).
_BLOCK_PIXELS = 1 << 16
#: Images with at least this many pixels are split across two threads (as emulator.core.emulate does).
_THREAD_MIN_PIXELS = 1 << 20


def check_rng(rng, error: type[Exception] = EmulationError) -> np.random.Generator:
    """A numpy Generator from ``rng`` (Generator, SeedSequence or non-negative int seed).

    None is refused: every random draw in exposim has an explicit seed.
    """
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, np.random.SeedSequence):
        return np.random.default_rng(rng)
    if rng is None:
        raise error("rng is required for noise: pass a seed (int) or a numpy.random.Generator")
    if isinstance(rng, bool) or not isinstance(rng, (int, np.integer)) or rng < 0:
        raise error(f"rng must be a non-negative integer seed, a numpy SeedSequence or Generator, got {rng!r}")
    return np.random.default_rng(int(rng))


def _normal_table() -> np.ndarray:
    """65536 standard-normal quantiles at (i + 1/2) / 65536, rescaled to zero mean, unit variance."""
    global _NORMAL_TABLE
    if _NORMAL_TABLE is None:
        inv = statistics.NormalDist().inv_cdf
        q = np.array([inv((i + 0.5) / NORMAL_LEVELS) for i in range(NORMAL_LEVELS)], dtype=np.float64)
        q -= q.mean()
        q /= math.sqrt(float(np.mean(q * q)))
        table = q.astype(np.float32)
        table.setflags(write=False)
        _NORMAL_TABLE = table
    return _NORMAL_TABLE


_NORMAL_TABLE: np.ndarray | None = None


def standard_normal(rng: np.random.Generator, shape) -> np.ndarray:
    """Standard-normal float32 draws: 16 random bits per draw index a quantile table.

    The table (:data:`NORMAL_LEVELS` quantiles, rescaled to exactly zero mean and unit
    variance) truncates the distribution at +-4.3 sigma (1.5e-5 of draws per side lie
    beyond); it is three times faster than ``Generator.standard_normal`` and is what the
    synthetic camera draws its noise with.  Draws ``ceil(n / 4)`` raw 64-bit outputs.
    """
    n = int(np.prod(shape))
    bits = rng.bit_generator.random_raw(-(-n // 4)).view(np.uint16)[:n].reshape(shape)
    if bits.ndim == 2:
        return cv2.LUT(bits, _normal_table())
    return np.take(_normal_table(), bits)


# ---------------------------------------------------------------------------- quantiser
class _Quantiser:
    """Linear exposure h (float32) -> DN as the camera quantises: ``black + #{theta_d <= h}``.

    ``theta_d = (g[d] + g[d + 1]) / 2`` for d = black .. white - 1 (float32), so the result
    is ``clip(floor(f(h) + 1/2), black, white)`` with f the piecewise-linear inverse of g.
    A grid uniform in ``v = sqrt(max(h - h0, 0))`` (:data:`QUANTISER_BINS` bins; h0 lies one
    level step below theta_0) stores per bin the DN of its left edge and the one decision
    level inside it (within a margin); a pixel's DN is that DN plus one comparison.  Bins
    holding two or more levels fall back to a binary search, so the result is exact.
    """

    def __init__(self, response: CameraResponse, bins: int = QUANTISER_BINS) -> None:
        g = response.g
        b, w = response.black_level, response.white_level
        if w >= 0x8000:
            raise EmulationError(f"{response.name}: white_level {w} too large for the quantiser")
        theta = (0.5 * (g[b:w] + g[b + 1: w + 1])).astype(np.float32)
        self.theta = theta
        self.black = b
        t64 = theta.astype(np.float64)
        step0 = float(t64[1] - t64[0]) if t64.size > 1 else 1.0
        self.h0 = np.float32(t64[0] - step0)
        h0 = float(self.h0)
        vmax = math.sqrt(float(t64[-1]) - h0)
        self.scale = np.float32((bins - 2) / vmax)
        scale = float(self.scale)
        k = np.arange(bins, dtype=np.float64)
        margin = _QUANTISER_MARGIN_BINS
        left_v = np.maximum(k - margin, 0.0) / scale
        right_v = (k + 1 + margin) / scale
        left = h0 + left_v * left_v
        right = h0 + right_v * right_v
        left[0] = -np.inf
        right[-1] = np.inf
        lo = np.searchsorted(t64, left, side="left")  # levels certainly <= every h of the bin
        inside = np.searchsorted(t64, right, side="right") - lo
        lut = (b + lo).astype(np.uint16)
        thr = np.full(bins, np.inf, dtype=np.float32)
        one = inside == 1
        thr[one] = theta[lo[one]]
        multi = inside > 1
        lut[multi] |= _MULTI
        self.lut, self.thr, self.bins = lut, thr, bins
        self.has_multi = bool(multi.any())

    def __call__(self, h: np.ndarray) -> np.ndarray:
        """DN (uint16) of a C-contiguous float32 image of h."""
        v = cv2.subtract(h, float(self.h0))
        cv2.max(v, 0.0, v)
        cv2.sqrt(v, v)
        # bin index round(v * scale - 1/2) = floor(v * scale) but at ties (covered by the
        # margin), saturated to 0..65535 by the conversion
        idx = cv2.addWeighted(v, float(self.scale), v, 0.0, -0.5, dtype=cv2.CV_16U)
        dn = cv2.LUT(idx, self.lut)
        above = cv2.compare(h, cv2.LUT(idx, self.thr), cv2.CMP_GE)
        cv2.add(dn, 1, dn, mask=above)
        if self.has_multi:
            flat = dn.reshape(-1)
            amb = np.flatnonzero(flat & _MULTI)
            if amb.size:
                flat[amb] = self.black + np.searchsorted(self.theta, h.reshape(-1)[amb], side="right")
        return dn


def quantise(h: np.ndarray, response: CameraResponse) -> np.ndarray:
    """DN of linear exposures ``h`` as the camera quantises them (uint16, same shape).

    ``clip(floor(f(h) + 1/2), black_level, white_level)`` with f the piecewise-linear
    inverse of ``response.g``, evaluated exactly in float32 (see :class:`_Quantiser`).
    """
    h = np.ascontiguousarray(h, dtype=np.float32)
    return _quantiser_of(response)(h)


_QUANTISERS: "OrderedDict[int, tuple[CameraResponse, _Quantiser]]" = OrderedDict()
_QLOCK = threading.Lock()


def _quantiser_of(response: CameraResponse) -> _Quantiser:
    key = id(response)
    with _QLOCK:
        hit = _QUANTISERS.get(key)
        if hit is not None and hit[0] is response:
            _QUANTISERS.move_to_end(key)
            return hit[1]
    q = _Quantiser(response)
    with _QLOCK:
        _QUANTISERS[key] = (response, q)
        while len(_QUANTISERS) > 8:
            _QUANTISERS.popitem(last=False)
    return q


# ---------------------------------------------------------------------------- tables
@dataclass(frozen=True, eq=False)
class NoiseTables:
    """Per-source-DN tables for one exposure ratio k, per Bayer phase (float64 unless noted).

    Index ``[p, d]``: phase p (:data:`PHASES` order, or a single row when the model is the
    same on every phase), source DN d in ``0..white_level``.

    Attributes
    ----------
    ratio : float
        k = target_ms / source_ms.
    electrons : ndarray
        Source signal estimate ``e_s = G * max(g(d), 0)``, electrons.
    var_live, var_emulated : ndarray
        Noise variance, electrons^2, of a live capture at the target and of the plain
        emulation (see :func:`emulator.core.emulate`, Notes), both including the target's
        quantisation.
    var_added : ndarray
        ``max(var_live - var_emulated, 0)``: what consistent emulation adds.
    mean_h, sigma_h : ndarray, float32
        ``k g(d)`` and ``sqrt(var_added) / G``: the emulated linear exposure and the
        standard deviation of the added noise, units of h.
    ratio_plain, ratio_consistent : ndarray, float32
        ``var_emulated / var_live``, and the same after consistent emulation (1 where noise
        is added, the plain ratio where the source is already noisier).
    """

    ratio: float
    electrons: np.ndarray
    var_live: np.ndarray
    var_emulated: np.ndarray
    var_added: np.ndarray
    mean_h: np.ndarray
    sigma_h: np.ndarray
    ratio_plain: np.ndarray
    ratio_consistent: np.ndarray
    any_added: bool
    all_added: bool
    _padded: dict = field(default_factory=dict, repr=False)

    def padded(self, name: str) -> np.ndarray:
        """A float32 table of 65536 entries for ``cv2.LUT`` over the (phase-offset) DN key."""
        hit = self._padded.get(name)
        if hit is None:
            flat = np.ascontiguousarray(getattr(self, name), dtype=np.float32).reshape(-1)
            hit = np.zeros(1 << 16, dtype=np.float32)
            hit[: flat.size] = flat
            hit[flat.size:] = flat[-1]
            hit.setflags(write=False)
            self._padded[name] = hit
        return hit


def response_slope(response: CameraResponse) -> np.ndarray:
    """g'(d) per DN (central differences, one-sided at the ends), float64, cached by identity."""
    key = id(response)
    hit = _SLOPES.get(key)
    if hit is not None and hit[0] is response:
        return hit[1]
    s = np.gradient(response.g)
    s.setflags(write=False)
    _SLOPES[key] = (response, s)
    if len(_SLOPES) > 16:
        _SLOPES.pop(next(iter(_SLOPES)))
    return s


_SLOPES: dict = {}


def build_tables(model: NoiseModel, k: float) -> NoiseTables:
    """Per-DN noise tables for ratio k (derivation: :func:`emulator.core.emulate`, Notes)."""
    response = model.response
    g = response.g
    slope = response_slope(response)
    dn = np.arange(response.white_level + 1, dtype=np.float64)
    target_dn = response.forward(k * g)
    slope_t = np.interp(target_dn, dn, slope)
    gains, reads = model.phase_values()
    rows = {name: [] for name in ("electrons", "var_live", "var_emulated", "var_added", "sigma_h", "ratio_plain",
                                  "ratio_consistent")}
    for gain, read in zip(gains, reads):
        e = gain * np.maximum(g, 0.0)
        q_src = (gain * slope) ** 2 / 12.0
        q_tgt = (gain * slope_t) ** 2 / 12.0
        var_live = k * e + read**2 + q_tgt
        if k == 1.0:  # the identity: the emulated image is the capture
            var_emu = var_live.copy()
        else:
            var_emu = k * k * (e + read**2 + q_src) + q_tgt
        added = np.maximum(var_live - var_emu, 0.0)
        plain = var_emu / var_live
        rows["electrons"].append(e)
        rows["var_live"].append(var_live)
        rows["var_emulated"].append(var_emu)
        rows["var_added"].append(added)
        rows["sigma_h"].append(np.sqrt(added) / gain)
        rows["ratio_plain"].append(plain)
        rows["ratio_consistent"].append(np.where(added > 0, 1.0, plain))
    arrays = {name: np.array(v) for name, v in rows.items()}
    for name in ("sigma_h", "ratio_plain", "ratio_consistent"):
        arrays[name] = arrays[name].astype(np.float32)
    mean_h = np.tile((k * g).astype(np.float32), (len(gains), 1))
    arrays["sigma_h"][arrays["var_added"] <= 0] = 0.0
    for v in list(arrays.values()) + [mean_h]:
        v.setflags(write=False)
    return NoiseTables(k, mean_h=mean_h, any_added=bool(np.any(arrays["sigma_h"] > 0)),
                       all_added=bool(np.all(arrays["sigma_h"] > 0)), **arrays)


# ---------------------------------------------------------------------------- emulation kernel
def consistent_noise(raw: np.ndarray, plain: np.ndarray, ratio: float, model: NoiseModel,
                     rng: np.random.Generator, *, tables: NoiseTables | None = None) -> np.ndarray:
    """Add the missing noise to a plain emulation (used by :func:`emulator.core.emulate`).

    Where the tables add variance, the output is ``quantise(k g(d) + sigma_h(d) z)`` with
    z standard normal (:func:`standard_normal`, one draw per pixel of ``raw``, in raster
    order); elsewhere the plain emulated DN.  ``raw`` and ``plain`` are checked by the caller.
    """
    t = tables if tables is not None else model.tables(ratio)
    if not t.any_added:
        return plain
    height, width = raw.shape
    key = model.key_image(raw)
    sigma_t, mean_t = t.padded("sigma_h"), t.padded("mean_h")
    quantiser = _quantiser_of(model.response)
    out = np.empty_like(plain)
    # all random bits first (raster order, 16 per pixel): the draw does not depend on blocking
    bits = rng.bit_generator.random_raw(-(-raw.size // 4)).view(np.uint16)[: raw.size].reshape(raw.shape)
    normal = _normal_table()
    rows = max(4, _BLOCK_PIXELS // max(width, 1))

    def work(start: int, stop: int) -> None:
        for r0 in range(start, stop, rows):
            sl = slice(r0, min(r0 + rows, stop))
            k = np.ascontiguousarray(key[sl])
            sigma = cv2.LUT(k, sigma_t)
            h = cv2.LUT(k, mean_t)
            z = cv2.LUT(np.ascontiguousarray(bits[sl]), normal)
            cv2.multiply(sigma, z, z)
            cv2.add(h, z, h)
            block = quantiser(h)
            if not t.all_added:
                cv2.copyTo(np.ascontiguousarray(plain[sl]), cv2.compare(sigma, 0.0, cv2.CMP_LE), block)
            out[sl] = block

    if raw.size >= _THREAD_MIN_PIXELS and height >= 2 * rows:
        half = height // 2
        list(lut_pool().map(lambda ab: work(*ab), [(0, half), (half, height)]))
    else:
        work(0, height)
    return out


def excess_map(raw: np.ndarray, ratio: float, model: NoiseModel, *, consistent: bool) -> np.ndarray:
    """Per-pixel variance ratio, emulated / live capture (float32, shape of ``raw``)."""
    t = model.tables(ratio)
    return cv2.LUT(model.key_image(raw), t.padded("ratio_consistent" if consistent else "ratio_plain"))
