"""Sensor noise for exposure emulation: the noise model, noise-consistent tables, in-situ estimation.

An emulated image carries its source bracket's noise scaled by the exposure ratio, not the
noise a capture at the target exposure would have (issue 14).  This module holds what the
emulator needs to correct that (:func:`emulator.emulate` with ``noise="consistent"``), and
an estimator of the noise figures from a recording's own bracket pairs.  numpy and OpenCV
only; no file access (arrays and dataclasses in, arrays and dataclasses out).

Sensor model (the one :mod:`synth.camera` implements), per Bayer site:

* electrons ``e = G * g(DN)`` where g is the inverse response (:class:`CameraResponse`,
  linear exposure h in table units) and ``G`` the *conversion gain* in electrons per unit
  of h (:attr:`NoiseModel.gain_e_per_h`).  G is a property of the sensor and its analogue
  gain, not of the exposure time: a capture at t ms of a radiance giving ``R`` units of h
  per ms collects ``G R t`` electrons.  The full well is the electron count that reaches
  the white level, ``G * g(white_level)``;
* temporal noise: photon shot noise (Poisson, variance e) plus read noise
  (Gaussian, ``read_noise_e`` rms), so ``var(e) = e + r^2`` electrons^2;
* quantisation to integer DN after the response: one DN at DN d spans ``G g'(d)``
  electrons, so it adds ``(G g'(d))^2 / 12`` electrons^2 wherever the noise dithers it
  (Sheppard's correction; exact to ``exp(-2 pi^2 sigma^2 / step^2)`` relative, i.e.
  for a noise of one DN or more);
* vignetting V(x) and photo-response non-uniformity scale the mean electrons of a pixel
  and are identical in every bracket: the model works on the electrons a pixel *has*
  (estimated from its own DN), so neither enters the noise equations, and both cancel in
  the exposure ratio as they do in eq. 2.  Dark current is neglected (exposures of at most
  tens of ms).

Per-site values: the gain and the read noise may be one number or a 2x2 tile over the
Bayer phases (row % 2, column % 2), e.g. when a camera applies white-balance gains to raw
data.  Tables are then built per phase.
"""

from __future__ import annotations

import math
import statistics
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

import cv2
import numpy as np

from emulator.errors import EmulationError, ExposimError
from emulator.response import CameraResponse

__all__ = [
    "NoiseModel",
    "NoiseModelError",
    "NoiseTables",
    "BracketPair",
    "NoiseEstimate",
    "estimate_noise_model",
    "check_rng",
    "standard_normal",
    "quantise",
    "PHASES",
]

#: The 2x2 Bayer phases (row % 2, column % 2) in raster order.
PHASES = ((0, 0), (0, 1), (1, 0), (1, 1))
#: How many per-ratio noise tables a model keeps.
TABLE_CACHE_SIZE = 32
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
#: Images with at least this many pixels are split across two threads (as emulator.emulate does).
_THREAD_MIN_PIXELS = 1 << 20


class NoiseModelError(ExposimError):
    """A noise model is invalid (non-finite or non-positive gain, negative read noise ...)
    or cannot be estimated from the data given."""


# ---------------------------------------------------------------------------- helpers
def _per_phase(value, name: str, *, positive: bool) -> tuple[float, ...]:
    """A scalar or a 2x2 tile as four floats in :data:`PHASES` order, validated."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise NoiseModelError(f"{name} must be a number or a 2x2 tile of numbers, got {value!r}") from None
    if arr.shape == ():
        arr = np.full((2, 2), float(arr))
    if arr.shape != (2, 2):
        raise NoiseModelError(f"{name} must be a number or a 2x2 tile (Bayer phases), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise NoiseModelError(f"{name} must be finite, got {value!r}")
    if positive and np.any(arr <= 0):
        raise NoiseModelError(f"{name} must be > 0, got {value!r}")
    if not positive and np.any(arr < 0):
        raise NoiseModelError(f"{name} must be >= 0, got {value!r}")
    return tuple(float(arr[i, j]) for i, j in PHASES)


def _as_tile(values: tuple[float, ...]):
    """Four per-phase floats back to a float (all equal) or a 2x2 tuple."""
    if all(v == values[0] for v in values):
        return values[0]
    return ((values[0], values[1]), (values[2], values[3]))


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
        emulation (see :func:`emulator.emulate`, Notes), both including the target's
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


# ---------------------------------------------------------------------------- model
@dataclass(frozen=True, eq=False)
class NoiseModel:
    """Temporal noise of a camera, in the units of its response.

    Parameters
    ----------
    response : CameraResponse
        The camera response (inverse table g, black and white levels) the model refers to;
        electrons are ``gain_e_per_h * g(DN)``.
    gain_e_per_h : float or 2x2
        Conversion gain G: electrons per unit of linear exposure h (g's table units;
        BorealHDR pcalib units have g(4095) = 255).  Finite, > 0.  One number, or one per
        Bayer phase (row % 2, column % 2).
    read_noise_e : float or 2x2
        Read noise, electrons rms (Gaussian), finite, >= 0.
    name : str
        Where the model came from (``synth:<camera>``, ``in-situ:<recording>`` ...).

    Notes
    -----
    Derived: :attr:`full_well_e` (electrons at the white level), :attr:`black_level`,
    :attr:`white_level`.  :meth:`tables` builds the per-ratio tables emulation uses.
    """

    response: CameraResponse
    gain_e_per_h: object
    read_noise_e: object = 0.0
    name: str = "custom"
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.response, CameraResponse):
            raise NoiseModelError(
                f"response must be an emulator CameraResponse, got {type(self.response).__name__}"
            )
        gains = _per_phase(self.gain_e_per_h, "gain_e_per_h", positive=True)
        reads = _per_phase(self.read_noise_e, "read_noise_e", positive=False)
        object.__setattr__(self, "gain_e_per_h", _as_tile(gains))
        object.__setattr__(self, "read_noise_e", _as_tile(reads))
        object.__setattr__(self, "_gains", gains)
        object.__setattr__(self, "_reads", reads)
        self._cache["tables"] = OrderedDict()
        self._cache["lock"] = threading.Lock()

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_full_well(cls, response: CameraResponse, full_well_e: float, read_noise_e=0.0,
                       *, name: str = "custom") -> "NoiseModel":
        """A model whose white level is reached at ``full_well_e`` electrons (G = full_well / g(white))."""
        try:
            fw = float(full_well_e)
        except (TypeError, ValueError):
            raise NoiseModelError(f"full_well_e must be a number of electrons, got {full_well_e!r}") from None
        if not (math.isfinite(fw) and fw > 0):
            raise NoiseModelError(f"full_well_e must be finite and > 0, got {full_well_e!r}")
        if not isinstance(response, CameraResponse):
            raise NoiseModelError(f"response must be an emulator CameraResponse, got {type(response).__name__}")
        top = float(response.g[response.white_level])
        if not top > 0:
            raise NoiseModelError(f"{response.name}: g(white_level) = {top!r} is not positive")
        return cls(response, fw / top, read_noise_e, name)

    @classmethod
    def from_dict(cls, data: dict, response: CameraResponse) -> "NoiseModel":
        """Rebuild from :meth:`to_dict` output and the response it refers to."""
        if not isinstance(data, dict):
            raise NoiseModelError(f"noise model description must be a mapping, got {type(data).__name__}")
        missing = [k for k in ("gain_e_per_h", "read_noise_e") if k not in data]
        if missing:
            raise NoiseModelError(f"noise model description lacks {', '.join(missing)}")
        return cls(response, data["gain_e_per_h"], data["read_noise_e"], str(data.get("name", "custom")))

    def to_dict(self) -> dict:
        """JSON-ready description (the response by name) plus derived values."""
        def plain(v):
            return [list(r) for r in v] if isinstance(v, tuple) else v
        return {
            "name": self.name,
            "gain_e_per_h": plain(self.gain_e_per_h),
            "read_noise_e": plain(self.read_noise_e),
            "response": self.response.name,
            "white_level": self.white_level,
            "black_level": self.black_level,
            "full_well_e": plain(self.full_well_e),
        }

    # ------------------------------------------------------------------ derived values
    @property
    def black_level(self) -> int:
        return self.response.black_level

    @property
    def white_level(self) -> int:
        return self.response.white_level

    @property
    def per_phase(self) -> bool:
        """True when gain or read noise differs between Bayer phases."""
        return len(set(self._gains)) > 1 or len(set(self._reads)) > 1

    @property
    def full_well_e(self):
        """Electrons at the white level, ``G * g(white_level)`` (per phase when G is)."""
        top = float(self.response.g[self.white_level])
        return _as_tile(tuple(gi * top for gi in self._gains))

    def phase_values(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(gains, read noises) per table row: one row, or four in :data:`PHASES` order."""
        if self.per_phase:
            return self._gains, self._reads
        return self._gains[:1], self._reads[:1]

    def matches(self, response: CameraResponse) -> bool:
        """Whether ``response`` is this model's response (same table and levels)."""
        r = self.response
        return response is r or (
            response.white_level == r.white_level
            and response.black_level == r.black_level
            and np.array_equal(response.g, r.g)
        )

    def variance_e(self, dn) -> np.ndarray:
        """Temporal noise variance (electrons^2, float64) of a capture whose DN is ``dn``.

        ``e + r^2 + (G g'(d))^2 / 12`` with ``e = G max(g(d), 0)``; one phase's values
        (the first) are used: call per phase for a per-phase model.
        """
        g, slope = self.response.g, _slope(self.response)
        d = np.clip(np.asarray(dn), 0, self.white_level).astype(np.intp)
        gain, read = self._gains[0], self._reads[0]
        return gain * np.maximum(g[d], 0.0) + read**2 + (gain * slope[d]) ** 2 / 12.0

    # ------------------------------------------------------------------ tables
    def tables(self, ratio: float) -> NoiseTables:
        """The cached :class:`NoiseTables` of exposure ratio k = ``ratio`` (> 0, finite)."""
        k = float(ratio)
        if not (math.isfinite(k) and k > 0):
            raise EmulationError(f"exposure ratio must be finite and > 0, got {ratio!r}")
        cache, lock = self._cache["tables"], self._cache["lock"]
        with lock:
            hit = cache.get(k)
            if hit is not None:
                cache.move_to_end(k)
                return hit
        tables = _build_tables(self, k)
        with lock:
            cache[k] = tables
            cache.move_to_end(k)
            while len(cache) > TABLE_CACHE_SIZE:
                cache.popitem(last=False)
        return tables

    def key_image(self, raw: np.ndarray) -> np.ndarray:
        """The table index of every pixel: ``raw``, or ``raw + phase * (white + 1)`` (uint16)."""
        if not self.per_phase:
            return raw
        shape = raw.shape
        offsets = self._cache.get(("offsets", shape))
        if offsets is None:
            rows = np.arange(shape[0])[:, None] % 2
            cols = np.arange(shape[1])[None, :] % 2
            offsets = ((2 * rows + cols) * (self.white_level + 1)).astype(np.uint16)
            offsets.setflags(write=False)
            self._cache[("offsets", shape)] = offsets
        return cv2.add(raw, offsets)

    def __repr__(self) -> str:
        return (f"NoiseModel({self.name!r}, gain_e_per_h={self.gain_e_per_h!r}, "
                f"read_noise_e={self.read_noise_e!r}, response={self.response.name!r})")


def _slope(response: CameraResponse) -> np.ndarray:
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


def _build_tables(model: NoiseModel, k: float) -> NoiseTables:
    """Per-DN noise tables for ratio k (derivation: :func:`emulator.emulate`, Notes)."""
    response = model.response
    g = response.g
    slope = _slope(response)
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
    """Add the missing noise to a plain emulation (used by :func:`emulator.emulate`).

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
        from emulator.emulate import _pool

        half = height // 2
        list(_pool().map(lambda ab: work(*ab), [(0, half), (half, height)]))
    else:
        work(0, height)
    return out


def excess_map(raw: np.ndarray, ratio: float, model: NoiseModel, *, consistent: bool) -> np.ndarray:
    """Per-pixel variance ratio, emulated / live capture (float32, shape of ``raw``)."""
    t = model.tables(ratio)
    return cv2.LUT(model.key_image(raw), t.padded("ratio_consistent" if consistent else "ratio_plain"))


# ---------------------------------------------------------------------------- in-situ estimation
@dataclass(frozen=True)
class BracketPair:
    """Two brackets of one sweep, shot close in time (e.g. t and 2t, ~46 ms apart).

    Attributes
    ----------
    raw_a, raw_b : ndarray, uint16 (H, W)
        Bayer mosaics in DN (one camera, one sweep).
    exposure_a_ms, exposure_b_ms : float
        Their exposure times, ms (different).
    label : str
        Names the pair in results (e.g. ``left c1 2->4``).
    """

    raw_a: np.ndarray
    exposure_a_ms: float
    raw_b: np.ndarray
    exposure_b_ms: float
    label: str = ""


@dataclass
class NoiseEstimate:
    """The result of :func:`estimate_noise_model`.

    Attributes
    ----------
    model : NoiseModel
        Pooled over Bayer phases (or per phase with ``per_phase=True``).
    gain_e_per_h, read_noise_e : float
        Pooled estimates (all phases and pairs in one fit).
    gain_std, read_noise_std : float
        Their formal standard errors (weighted least squares, scaled by the fit's residual
        dispersion when that exceeds 1).
    per_channel : dict
        Phase name -> {"gain_e_per_h", "read_noise_e", "gain_std", "read_noise_std", "n_bins"}.
    per_pair : list of dict
        One fit per bracket pair (all phases): label, exposures, the integer shift applied
        (sub-lattice pixels), pixels used, gain and read noise.
    spread : dict
        Over the per-pair fits: median, 16th/84th percentiles, min, max and the relative
        half-width ``(p84 - p16) / 2 / median`` of gain and read noise.
    bins : dict of ndarray
        The photon-transfer points behind the fit, one per (pair, phase, intensity bin):
        ``pair``, ``phase``, ``signal`` (mean h per ms), ``x_shot``, ``x_read``,
        ``variance`` (of the difference), ``quantisation``, ``n``, ``weight`` (final).
    warnings : list of str
    """

    model: NoiseModel
    gain_e_per_h: float
    read_noise_e: float
    gain_std: float
    read_noise_std: float
    per_channel: dict
    per_pair: list
    spread: dict
    bins: dict
    warnings: list

    @property
    def full_well_e(self) -> float:
        return self.gain_e_per_h * float(self.model.response.g[self.model.white_level])

    def to_dict(self) -> dict:
        """JSON-ready summary (no per-bin arrays)."""
        return {
            "model": self.model.to_dict(),
            "gain_e_per_h": self.gain_e_per_h,
            "read_noise_e": self.read_noise_e,
            "gain_std": self.gain_std,
            "read_noise_std": self.read_noise_std,
            "full_well_e": self.full_well_e,
            "per_channel": self.per_channel,
            "per_pair": self.per_pair,
            "spread": self.spread,
            "n_bins": int(self.bins["n"].size),
            "warnings": list(self.warnings),
        }


def _phase_names(bayer_pattern: str | None) -> list[str]:
    if bayer_pattern is None:
        return [f"r{i}c{j}" for i, j in PHASES]
    pattern = str(bayer_pattern).upper()
    if len(pattern) != 4 or set(pattern) - set("RGB"):
        raise NoiseModelError(f"bayer_pattern must be like 'RGGB', got {bayer_pattern!r}")
    names, seen = [], {}
    for c in pattern:
        seen[c] = seen.get(c, 0) + 1
        names.append(c if pattern.count(c) == 1 else f"{c}{seen[c]}")
    return names


def _truncated_variance_factor(c: float) -> float:
    """Var of a standard normal truncated to [-c, c]."""
    phi = math.exp(-0.5 * c * c) / math.sqrt(2 * math.pi)
    mass = math.erf(c / math.sqrt(2))
    return 1.0 - 2.0 * c * phi / mass


def robust_variance(x: np.ndarray, clip: float = 4.0, iterations: int = 4) -> tuple[float, int]:
    """Variance of the Gaussian core of ``x``: sigma clipping at ``clip`` sigma.

    Starts from the median and 1.4826 MAD, keeps ``|x - m| <= clip s``, re-estimates
    mean and standard deviation of the kept values (corrected for the truncation of a
    normal at ``clip`` sigma), ``iterations`` times.  Returns (variance, values kept).
    """
    x = np.asarray(x, dtype=np.float64)
    if x.size < 3:
        return float("nan"), int(x.size)
    m = float(np.median(x))
    s = 1.4826 * float(np.median(np.abs(x - m)))
    if not s > 0:
        s = float(np.std(x))
    if not s > 0:
        return 0.0, int(x.size)
    factor = _truncated_variance_factor(clip)
    kept = x
    for _ in range(iterations):
        kept = x[np.abs(x - m) <= clip * s]
        if kept.size < 3:
            return float("nan"), int(kept.size)
        m = float(kept.mean())
        s = math.sqrt(float(kept.var(ddof=1)) / factor)
    return s * s, int(kept.size)


def _align_shift(ha: np.ndarray, hb: np.ndarray, max_shift: int) -> tuple[int, int]:
    """Integer (dy, dx) with ``hb[y + dy, x + dx] ~ ha[y, x]`` (phase correlation of log h)."""
    la = np.log(np.maximum(ha, 1e-6)).astype(np.float32)
    lb = np.log(np.maximum(hb, 1e-6)).astype(np.float32)
    window = cv2.createHanningWindow((la.shape[1], la.shape[0]), cv2.CV_32F)
    (dx, dy), _ = cv2.phaseCorrelate(la - float(la.mean()), lb - float(lb.mean()), window)
    dy, dx = int(round(dy)), int(round(dx))
    if abs(dy) > max_shift or abs(dx) > max_shift:
        return 0, 0
    return dy, dx


def _overlap(a: np.ndarray, b: np.ndarray, dy: int, dx: int) -> tuple[np.ndarray, np.ndarray]:
    """Views of a and b where ``b[y + dy, x + dx]`` pairs with ``a[y, x]``."""
    h, w = a.shape
    ya, yb = (slice(0, h - dy), slice(dy, h)) if dy >= 0 else (slice(-dy, h), slice(0, h + dy))
    xa, xb = (slice(0, w - dx), slice(dx, w)) if dx >= 0 else (slice(-dx, w), slice(0, w + dx))
    return a[ya, xa], b[yb, xb]


def _pair_points(pair: BracketPair, response: CameraResponse, slope: np.ndarray, *, limits, n_bins: int,
                 flat_fraction: float, min_pixels: int, align: bool, clip: float):
    """Photon-transfer points of one pair: per phase and intensity bin (see estimate_noise_model)."""
    ta, tb = float(pair.exposure_a_ms), float(pair.exposure_b_ms)
    g = response.g
    planes_a = [np.ascontiguousarray(pair.raw_a[i::2, j::2]) for i, j in PHASES]
    planes_b = [np.ascontiguousarray(pair.raw_b[i::2, j::2]) for i, j in PHASES]
    shift = (0, 0)
    if align:
        # one shift for all phases, from the 2x2-binned exposure-normalised images
        ha = sum(g[p] for p in planes_a) / ta
        hb = sum(g[p] for p in planes_b) / tb
        # both clipped to what neither saturates, so saturation does not pull the match
        top = min(ha.max(), hb.max())
        shift = _align_shift(np.minimum(ha, top), np.minimum(hb, top), max_shift=min(ha.shape) // 4)
    points = []
    for p, (a, b) in enumerate(zip(planes_a, planes_b)):
        a, b = _overlap(a, b, *shift)
        ua, ub = g[a], g[b]
        signal = (ua + ub) / (ta + tb)  # total signal / total time: uncorrelated with diff (shot noise)
        diff = ub / tb - ua / ta
        lo, hi = limits(signal, ta, tb, p)
        usable = (signal >= lo) & (signal <= hi)
        if np.count_nonzero(usable) < min_pixels:
            continue
        blur = cv2.GaussianBlur(signal.astype(np.float32), (0, 0), 1.0)
        gx = cv2.Sobel(blur, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
        gy = cv2.Sobel(blur, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
        grad = np.sqrt(gx * gx + gy * gy) / np.maximum(blur, 1e-12)
        qterm = (slope[a] ** 2 / ta**2 + slope[b] ** 2 / tb**2) / 12.0
        s, d, gr, qt = signal[usable], diff[usable], grad[usable], qterm[usable]
        edges = np.geomspace(float(s.min()), float(s.max()) * (1 + 1e-9), n_bins + 1)
        which = np.searchsorted(edges, s, side="right") - 1
        order = np.argsort(which, kind="stable")
        starts = np.searchsorted(which[order], np.arange(n_bins + 1))
        for k in range(n_bins):
            idx = order[starts[k]: starts[k + 1]]
            if idx.size < min_pixels:
                continue
            if flat_fraction < 1.0:
                keep = max(min_pixels, int(round(flat_fraction * idx.size)))
                if keep < idx.size:
                    idx = idx[np.argpartition(gr[idx], keep - 1)[:keep]]
            var, n = robust_variance(d[idx], clip)
            if not math.isfinite(var) or n < min_pixels:
                continue
            mean_s = float(s[idx].mean())
            points.append((p, mean_s, mean_s * (1 / ta + 1 / tb), 1 / ta**2 + 1 / tb**2, var,
                           float(qt[idx].mean()), n))
    return points, shift


def _fit(x_shot, x_read, y, q, n, *, huber: float = 3.0, iterations: int = 8):
    """Weighted least squares ``y - q = alpha x_shot + beta x_read``; variance weights, Huber.

    Weights ``(n - 1) / (2 pred^2)`` (the variance of a variance estimate from n normal
    values), iterated with the prediction, times Huber weights on the standardised
    residuals.  Returns (alpha, beta, covariance, final weights).
    """
    X = np.column_stack([x_shot, x_read])
    scale = np.abs(X).max(axis=0)
    scale[scale == 0] = 1.0
    Xs = X / scale
    target = y - q
    w = np.ones_like(y)
    coef = np.linalg.lstsq(Xs, target, rcond=None)[0]
    hub = np.ones_like(y)
    for _ in range(iterations):
        pred = np.maximum(Xs @ coef + q, 1e-300)
        w = (n - 1) / (2 * pred**2)
        res = (target - Xs @ coef) * np.sqrt(w)
        hub = np.minimum(1.0, huber / np.maximum(np.abs(res), 1e-300))
        ww = w * hub
        A = Xs.T @ (Xs * ww[:, None])
        coef = np.linalg.solve(A, Xs.T @ (ww * target))
    ww = w * hub
    A = Xs.T @ (Xs * ww[:, None])
    res = (target - Xs @ coef) * np.sqrt(ww)
    dof = max(len(y) - 2, 1)
    dispersion = max(1.0, float(res @ res) / dof)
    cov = np.linalg.inv(A) * dispersion
    coef = coef / scale
    cov = cov / np.outer(scale, scale)
    return float(coef[0]), float(coef[1]), cov, ww


def _gain_read(alpha: float, beta: float, cov: np.ndarray) -> tuple[float, float, float, float]:
    """(G, r, std G, std r) from alpha = 1/G, beta = r^2/G^2 (delta method); r = 0 if beta <= 0."""
    if not alpha > 0:
        return float("nan"), float("nan"), float("nan"), float("nan")
    gain = 1.0 / alpha
    sg = math.sqrt(max(cov[0, 0], 0.0)) / alpha**2
    if beta <= 0:
        return gain, 0.0, sg, float("nan")
    r = math.sqrt(beta) / alpha
    jac = np.array([-math.sqrt(beta) / alpha**2, 0.5 / (alpha * math.sqrt(beta))])
    sr = math.sqrt(max(float(jac @ cov @ jac), 0.0))
    return gain, r, sg, sr


def _percentiles(values) -> dict:
    v = np.asarray([x for x in values if math.isfinite(x)], dtype=np.float64)
    if v.size == 0:
        return {"n": 0}
    p16, med, p84 = (float(x) for x in np.percentile(v, [16, 50, 84]))
    return {"n": int(v.size), "median": med, "p16": p16, "p84": p84, "min": float(v.min()),
            "max": float(v.max()), "relative_half_width": (p84 - p16) / 2 / med if med else float("nan")}


def estimate_noise_model(
    pairs,
    response: CameraResponse,
    *,
    n_bins: int = 32,
    flat_fraction: float = 0.5,
    align: bool = True,
    clip_sigmas: float = 5.0,
    min_pixels: int = 200,
    per_phase: bool = False,
    bayer_pattern: str | None = "RGGB",
    name: str = "in-situ",
) -> NoiseEstimate:
    """Estimate conversion gain and read noise from a recording's own bracket pairs.

    Photon transfer from cross-bracket differences: for two brackets a, b of one sweep
    (exposures t_a, t_b, shot ~46 ms apart) the exposure-normalised images
    ``g(d_a) / t_a`` and ``g(d_b) / t_b`` agree up to noise, motion and response error
    (vignetting cancels: same pixel).

    Parameters
    ----------
    pairs : sequence of BracketPair
        Pairs of brackets (any exposures, different); more pairs, better estimate.
    response : CameraResponse
        The recording's response (g, levels); the gain comes out in electrons per its unit.
    n_bins : int
        Intensity bins per pair and Bayer phase (log-spaced in signal).
    flat_fraction : float
        In each bin, keep this fraction of pixels with the smallest relative gradient of
        the (2x2-phase) signal image: motion between the shots moves edges, not flat areas.
    align : bool
        Apply the integer shift (on the Bayer sub-lattice) found by phase correlation of the
        two images before differencing; an integer shift moves no noise between pixels.
    clip_sigmas : float
        Pixels are used only where both brackets' expected signal lies this many noise
        standard deviations inside the clip levels (second pass, with the first-pass model).
    min_pixels : int
        Smallest pixel count of a bin.
    per_phase : bool
        Return a per-Bayer-phase model (2x2 gain and read noise) instead of the pooled one.
    bayer_pattern : str or None
        Names the phases in ``per_channel`` ("RGGB" -> R, G1, G2, B).
    name : str
        Model name.

    Returns
    -------
    NoiseEstimate

    Raises
    ------
    NoiseModelError
        No pairs, a pair with equal or invalid exposures or mismatched shapes, or too few
        usable pixels to fit.

    Notes
    -----
    Per pixel, with ``u = g(d)`` (units of h), the signal ``S = (u_a + u_b) / (t_a + t_b)``
    (h per ms) and the difference ``D = u_b / t_b - u_a / t_a``:

    ``var(u) = (e + r^2) / G^2 + g'(d)^2 / 12`` with ``e = G S t``, so

    ``var(D) = (1/G) S (1/t_a + 1/t_b) + (r^2/G^2) (1/t_a^2 + 1/t_b^2) + Q``,
    ``Q = (g'(d_a)^2 / t_a^2 + g'(d_b)^2 / t_b^2) / 12``.

    S and D are uncorrelated for shot noise (``t_b var(u_b/t_b) - t_a var(u_a/t_a)`` has
    no shot term), so binning by S does not bias var(D).  In each bin (per pair and
    phase): the mean S, mean Q and a robust variance of D (sigma clipping at 4 sigma around
    the bin's own mean, which also removes a response error common to the bin).  Then
    ``var - Q = alpha x_shot + beta x_read`` (``x_shot = S (1/t_a + 1/t_b)``,
    ``x_read = 1/t_a^2 + 1/t_b^2``) by weighted least squares with Huber weights gives
    ``G = 1/alpha`` and ``r = sqrt(beta) / alpha``.  Pairs with different exposures
    separate the two terms; one pair alone also does (slope and intercept).

    Usable pixels: a first pass keeps signals between 2 % and 90 % of the response range
    in both brackets; the second keeps those whose expected electrons lie ``clip_sigmas``
    standard deviations inside the electrons of the first and last decision levels.
    A response whose g(black) is above zero (BorealHDR: 0.17 of 255) clips the darkest
    electrons to black, so the read-noise regime (e < r^2) may be out of reach and r is
    then identified only by extrapolation: its uncertainty says so.
    """
    pairs = list(pairs)
    if not pairs:
        raise NoiseModelError("no bracket pairs given")
    if not isinstance(response, CameraResponse):
        raise NoiseModelError(f"response must be an emulator CameraResponse, got {type(response).__name__}")
    for i, pr in enumerate(pairs):
        where = f"pair {i} ({pr.label or 'unnamed'})"
        for raw in (pr.raw_a, pr.raw_b):
            if not isinstance(raw, np.ndarray) or raw.dtype != np.uint16 or raw.ndim != 2:
                raise NoiseModelError(f"{where}: images must be 2-D uint16 Bayer mosaics")
        if pr.raw_a.shape != pr.raw_b.shape:
            raise NoiseModelError(f"{where}: shapes differ ({pr.raw_a.shape} vs {pr.raw_b.shape})")
        if min(pr.raw_a.shape) < 16:
            raise NoiseModelError(f"{where}: images too small ({pr.raw_a.shape})")
        for t in (pr.exposure_a_ms, pr.exposure_b_ms):
            if not (isinstance(t, (int, float, np.floating, np.integer)) and math.isfinite(t) and t > 0):
                raise NoiseModelError(f"{where}: exposure {t!r} must be finite and > 0 ms")
        if pr.exposure_a_ms == pr.exposure_b_ms:
            raise NoiseModelError(f"{where}: both brackets have {pr.exposure_a_ms} ms; need different exposures")
    if not 0 < flat_fraction <= 1:
        raise NoiseModelError(f"flat_fraction must be in (0, 1], got {flat_fraction!r}")
    names = _phase_names(bayer_pattern)
    slope = _slope(response)
    g = response.g
    b, w = response.black_level, response.white_level
    theta_lo = 0.5 * (g[b] + g[b + 1])
    theta_hi = 0.5 * (g[w - 1] + g[w])
    span = theta_hi - max(theta_lo, 0.0)
    warnings: list[str] = []

    def pass_one(signal, ta, tb, p):
        lo = (max(theta_lo, 0.0) + 0.02 * span) / min(ta, tb)
        hi = (max(theta_lo, 0.0) + 0.90 * span) / max(ta, tb)
        return lo, hi

    def run(limits):
        pts, shifts = [], []
        for i, pr in enumerate(pairs):
            p_pts, shift = _pair_points(pr, response, slope, limits=limits, n_bins=n_bins,
                                        flat_fraction=flat_fraction, min_pixels=min_pixels, align=align,
                                        clip=4.0)
            pts += [(i,) + t for t in p_pts]
            shifts.append(shift)
        if len(pts) < 3:
            raise NoiseModelError(
                f"only {len(pts)} usable intensity bin(s) in {len(pairs)} pair(s): too few unclipped, flat pixels "
                f"(min_pixels={min_pixels})"
            )
        arr = np.array(pts, dtype=np.float64)
        cols = dict(pair=arr[:, 0].astype(int), phase=arr[:, 1].astype(int), signal=arr[:, 2], x_shot=arr[:, 3],
                    x_read=arr[:, 4], variance=arr[:, 5], quantisation=arr[:, 6], n=arr[:, 7])
        return cols, shifts

    cols, _ = run(pass_one)
    alpha, beta, _, _ = _fit(cols["x_shot"], cols["x_read"], cols["variance"], cols["quantisation"], cols["n"])
    if not alpha > 0:
        raise NoiseModelError(f"first pass found no positive shot-noise slope (alpha = {alpha:.3g}): "
                              "the differences do not grow with the signal")
    gain1 = 1.0 / alpha
    read1 = math.sqrt(beta) / alpha if beta > 0 else 0.0
    e_lo, e_hi = gain1 * theta_lo, gain1 * theta_hi

    def pass_two(signal, ta, tb, p):
        # smallest signal s with G s t - c sqrt(G s t + r^2) >= e_lo for the shorter bracket,
        # largest with G s t + c sqrt(G s t + r^2) <= e_hi for the longer (solved on a grid)
        c = clip_sigmas
        e = np.geomspace(max(e_lo, 1e-3) + 1e-3, max(e_hi, 1.0), 4096)
        sd = np.sqrt(e + read1**2)
        ok_lo = e - c * sd >= e_lo
        ok_hi = e + c * sd <= e_hi
        if not ok_lo.any() or not ok_hi.any():
            return np.inf, -np.inf
        lo_e = e[np.argmax(ok_lo)]
        hi_e = e[len(e) - 1 - np.argmax(ok_hi[::-1])]
        return lo_e / (gain1 * min(ta, tb)), hi_e / (gain1 * max(ta, tb))

    cols, shifts = run(pass_two)
    alpha, beta, cov, weights = _fit(cols["x_shot"], cols["x_read"], cols["variance"], cols["quantisation"],
                                     cols["n"])
    gain, read, sg, sr = _gain_read(alpha, beta, cov)
    if not math.isfinite(gain):
        raise NoiseModelError(f"no positive shot-noise slope (alpha = {alpha:.3g})")
    if beta <= 0:
        warnings.append(f"read-noise term fitted <= 0 (beta = {beta:.3g}): read noise set to 0; the data do not "
                        "reach the read-noise regime")
    cols["weight"] = weights

    per_channel = {}
    phase_gain, phase_read = [], []
    for p, nm in enumerate(names):
        m = cols["phase"] == p
        if np.count_nonzero(m) < 3:
            per_channel[nm] = {"n_bins": int(np.count_nonzero(m))}
            phase_gain.append(gain)
            phase_read.append(read)
            continue
        a_p, b_p, c_p, _ = _fit(cols["x_shot"][m], cols["x_read"][m], cols["variance"][m], cols["quantisation"][m],
                                cols["n"][m])
        gp, rp, sgp, srp = _gain_read(a_p, b_p, c_p)
        per_channel[nm] = {"gain_e_per_h": gp, "read_noise_e": rp, "gain_std": sgp, "read_noise_std": srp,
                           "n_bins": int(np.count_nonzero(m))}
        phase_gain.append(gp if math.isfinite(gp) else gain)
        phase_read.append(rp if math.isfinite(rp) else read)

    per_pair = []
    for i, pr in enumerate(pairs):
        m = cols["pair"] == i
        entry = {"label": pr.label, "exposure_a_ms": float(pr.exposure_a_ms), "exposure_b_ms": float(pr.exposure_b_ms),
                 "shift_px": [2 * s for s in shifts[i]], "n_bins": int(np.count_nonzero(m)),
                 "n_pixels": int(cols["n"][m].sum())}
        if np.count_nonzero(m) >= 3:
            a_i, b_i, c_i, _ = _fit(cols["x_shot"][m], cols["x_read"][m], cols["variance"][m],
                                    cols["quantisation"][m], cols["n"][m])
            gi, ri, sgi, sri = _gain_read(a_i, b_i, c_i)
            entry.update(gain_e_per_h=gi, read_noise_e=ri, gain_std=sgi, read_noise_std=sri)
        per_pair.append(entry)
    spread = {"gain_e_per_h": _percentiles(e.get("gain_e_per_h", float("nan")) for e in per_pair),
              "read_noise_e": _percentiles(e.get("read_noise_e", float("nan")) for e in per_pair)}

    if per_phase:
        tile = lambda v: ((v[0], v[1]), (v[2], v[3]))  # noqa: E731
        model = NoiseModel(response, tile(phase_gain), tile(phase_read), name)
    else:
        model = NoiseModel(response, gain, read, name)
    return NoiseEstimate(model, gain, read, sg, sr, per_channel, per_pair, spread, cols, warnings)
