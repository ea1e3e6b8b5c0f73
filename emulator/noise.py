"""Sensor noise for exposure emulation: the noise model, noise-consistent tables, in-situ estimation.

An emulated image carries its source bracket's noise scaled by the exposure ratio, not the
noise a capture at the target exposure would have (issue 14).  This module holds what the
emulator needs to correct that (:func:`emulator.emulate` with ``noise="consistent"``), an
estimator of the noise figures from a recording's own brackets (:func:`bracket_groups`,
:func:`estimate_noise_model`), the measured variance ratio of emulated against live images
(:func:`noise_variance_ratio`), and the model's JSON form (:meth:`NoiseModel.to_json`,
:meth:`NoiseModel.from_json`; :func:`write_noise_model` / :func:`read_noise_model` are the
only file access here, a reader/writer pair meant to move into ``emulator/io``).
numpy and OpenCV only.

Sensor model (the one :mod:`synth.imaging` implements), per Bayer site:

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

import hashlib
import json
import math
import os
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
    "BracketGroup",
    "bracket_groups",
    "NoiseEstimate",
    "estimate_noise_model",
    "response_fingerprint",
    "noise_variance_ratio",
    "VarianceRatio",
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


NOISE_MODEL_FORMAT = "exposim.noise_model"
NOISE_MODEL_VERSION = 1


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
        """Rebuild from :meth:`to_dict` output and the response it refers to.

        When ``data`` records the response's levels and fingerprint (:meth:`to_dict` does),
        a different ``response`` is refused: the gain is in units of that table.
        """
        if not isinstance(data, dict):
            raise NoiseModelError(f"noise model description must be a mapping, got {type(data).__name__}")
        missing = [k for k in ("gain_e_per_h", "read_noise_e") if k not in data]
        if missing:
            raise NoiseModelError(f"noise model description lacks {', '.join(missing)}")
        if not isinstance(response, CameraResponse):
            raise NoiseModelError(f"response must be an emulator CameraResponse, got {type(response).__name__}")
        for key, have in (("white_level", response.white_level), ("black_level", response.black_level),
                          ("response_sha256", response_fingerprint(response))):
            if key in data and data[key] != have:
                raise NoiseModelError(
                    f"noise model {data.get('name', '?')!r} refers to response {data.get('response', '?')!r} "
                    f"({key} {data[key]!r}), not to the response given ({response.name!r}, {key} {have!r})")
        return cls(response, data["gain_e_per_h"], data["read_noise_e"], str(data.get("name", "custom")))

    def to_dict(self) -> dict:
        """JSON-ready description (format tag, the response by name and fingerprint) plus derived values."""
        def plain(v):
            return [list(r) for r in v] if isinstance(v, tuple) else v
        return {
            "format": NOISE_MODEL_FORMAT,
            "version": NOISE_MODEL_VERSION,
            "name": self.name,
            "gain_e_per_h": plain(self.gain_e_per_h),
            "read_noise_e": plain(self.read_noise_e),
            "response": self.response.name,
            "white_level": self.white_level,
            "black_level": self.black_level,
            "full_well_e": plain(self.full_well_e),
            "response_sha256": response_fingerprint(self.response),
        }

    def to_json(self, **extra) -> str:
        """JSON text of :meth:`to_dict` (plus ``extra`` top-level entries, e.g. an estimate's summary)."""
        data = self.to_dict()
        data.update(extra)
        return json.dumps(data, indent=2, sort_keys=False, allow_nan=False) + "\n"

    @classmethod
    def from_json(cls, text: str, response: CameraResponse, *, source: str = "noise model") -> "NoiseModel":
        """Parse :meth:`to_json` text; ``source`` (e.g. the file name) prefixes every error."""
        try:
            data = json.loads(text)
        except (TypeError, json.JSONDecodeError) as exc:
            raise NoiseModelError(f"{source}: malformed JSON ({exc})") from None
        if not isinstance(data, dict) or data.get("format") != NOISE_MODEL_FORMAT:
            raise NoiseModelError(f"{source}: not an exposim noise model (expected \"format\": "
                                  f"\"{NOISE_MODEL_FORMAT}\")")
        if data.get("version") != NOISE_MODEL_VERSION:
            raise NoiseModelError(f"{source}: unsupported noise model version {data.get('version')!r} "
                                  f"(this exposim reads {NOISE_MODEL_VERSION})")
        try:
            return cls.from_dict(data, response)
        except NoiseModelError as exc:
            raise NoiseModelError(f"{source}: {exc}") from None

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


def response_fingerprint(response: CameraResponse) -> str:
    """SHA-256 of a response's table (float64, little-endian) and levels: what a noise model refers to."""
    h = hashlib.sha256(np.ascontiguousarray(response.g, dtype="<f8").tobytes())
    h.update(f"{response.black_level}:{response.white_level}".encode())
    return h.hexdigest()


def json_safe(value):
    """Non-finite floats (an undetermined standard error) as None, recursively."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


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
#: The high-pass applied to difference images (separable second difference, [1, -2, 1] in
#: rows and in columns, on one Bayer plane): it removes anything locally linear in x or in
#: y, such as the residue of a sub-pixel motion between the shots over smooth texture.
_HP = np.outer([1.0, -2.0, 1.0], [1.0, -2.0, 1.0])
#: Its squared coefficients: the variance of the output at a pixel is this kernel applied
#: to the per-pixel variances of the input (independent noise); they sum to 36.
_HP_SQ = _HP * _HP


@dataclass(frozen=True)
class BracketGroup:
    """Two or three consecutive brackets of one sweep of one camera.

    Attributes
    ----------
    raws : tuple of ndarray, uint16 (H, W)
        Bayer mosaics in DN, in capture order.
    exposures_ms : tuple of float
        Their exposure times, ms.
    times_s : tuple of float or None
        Their capture instants, seconds (any origin), increasing; None means equally spaced.
    label : str
        Names the group in results (e.g. ``left c1 2-4-8``).

    Notes
    -----
    :meth:`weights` are the coefficients of the exposure-normalised images in the difference
    :func:`estimate_noise_model` measures: ``(-1, 1)`` for a pair; for a triple
    ``(-(tau_c - tau_b), tau_c - tau_a, -(tau_b - tau_a)) / (tau_c - tau_a)``, i.e. the middle
    shot minus the linear interpolation of the outer two to its instant, which cancels any
    motion (or illumination change) linear in time.
    """

    raws: tuple
    exposures_ms: tuple
    times_s: tuple | None = None
    label: str = ""

    @classmethod
    def pair(cls, raw_a, exposure_a_ms, raw_b, exposure_b_ms, label: str = "") -> "BracketGroup":
        return cls((raw_a, raw_b), (exposure_a_ms, exposure_b_ms), None, label)

    def weights(self) -> tuple[float, ...]:
        if len(self.raws) == 2:
            return (-1.0, 1.0)
        ta, tb, tc = (0.0, 1.0, 2.0) if self.times_s is None else (float(t) for t in self.times_s)
        span = tc - ta
        return (-(tc - tb) / span, 1.0, -(tb - ta) / span)


def bracket_groups(sequence, *, size: int = 3, cameras=None, cycles=None, max_groups: int | None = None,
                   max_gap: float = 1.5) -> list[BracketGroup]:
    """Groups of ``size`` (2 or 3) consecutive shots of every sweep of a recording, images loaded.

    Parameters
    ----------
    sequence : emulator.dataset.Sequence
        The recording (:func:`emulator.dataset.load_sequence`).
    size : int
        3 (default): triples, whose time-interpolated difference cancels motion linear in
        time; 2: pairs of neighbouring brackets.
    cameras : sequence of str or None
        Cameras to use (default: all of the sequence's).
    cycles : iterable of int or None
        Cycle indices to use (default: all).
    max_groups : int or None
        At most this many groups, spread evenly over the candidates (deterministic).
    max_gap : float
        Shots of a group must follow each other within ``max_gap`` shot periods (the median
        interval between shots): a missing bracket breaks a group.

    Returns
    -------
    list of BracketGroup
        Capture order within a group; ``times_s`` from the file timestamps.
    """
    from emulator.dataset import Sequence

    if not isinstance(sequence, Sequence):
        raise NoiseModelError(f"sequence must be an emulator.dataset.Sequence, got {type(sequence).__name__}")
    if size not in (2, 3):
        raise NoiseModelError(f"size must be 2 (pairs) or 3 (triples), got {size!r}")
    cams = tuple(sequence.cameras if cameras is None else cameras)
    unknown = [c for c in cams if c not in sequence.cameras]
    if unknown:
        raise NoiseModelError(f"{sequence.path}: no camera {', '.join(map(repr, unknown))} "
                              f"(has {', '.join(sequence.cameras)})")
    wanted = None if cycles is None else {int(c) for c in cycles}
    stamps = sorted({f.timestamp_ns for c in sequence for cam in cams for f in c.frames.get(cam, {}).values()})
    period = float(np.median(np.diff(stamps))) if len(stamps) > 1 else 0.0
    candidates = []
    for cycle in sequence:
        if wanted is not None and cycle.index not in wanted:
            continue
        for cam in cams:
            shots = sorted(cycle.frames.get(cam, {}).values(), key=lambda f: f.timestamp_ns)
            for k in range(len(shots) - size + 1):
                win = shots[k: k + size]
                gaps = np.diff([f.timestamp_ns for f in win])
                if period > 0 and np.any(gaps > max_gap * period):
                    continue
                candidates.append((cam, cycle.index, win))
    if max_groups is not None and len(candidates) > max_groups:
        pick = np.unique(np.round(np.linspace(0, len(candidates) - 1, int(max_groups))).astype(int))
        candidates = [candidates[i] for i in pick]
    groups = []
    for cam, index, win in candidates:
        t0 = win[0].timestamp_ns
        groups.append(BracketGroup(
            tuple(f.load() for f in win), tuple(float(f.exposure_ms) for f in win),
            tuple((f.timestamp_ns - t0) * 1e-9 for f in win),
            f"{cam} c{index} " + "-".join(f"{f.exposure_ms:g}" for f in win)))
    return groups


@dataclass
class NoiseEstimate:
    """The result of :func:`estimate_noise_model`.

    Attributes
    ----------
    model : NoiseModel
        Pooled over Bayer phases (or per phase with ``per_phase=True``).
    gain_e_per_h, read_noise_e : float
        Pooled estimates (all phases and groups in one fit).
    gain_std, read_noise_std : float
        Their formal standard errors (weighted least squares, scaled by the fit's residual
        dispersion when that exceeds 1).
    per_channel : dict
        Phase name -> {"gain_e_per_h", "read_noise_e", "gain_std", "read_noise_std", "n_bins"}.
    per_group : list of dict
        One fit per bracket group (all phases): label, exposures, the integer shift applied
        to each shot (full-resolution pixels), pixels used, gain and read noise.
    spread : dict
        Over the per-group fits: median, 16th/84th percentiles, min, max and the relative
        half-width ``(p84 - p16) / 2 / median`` of gain and read noise.
    bins : dict of ndarray
        The photon-transfer points behind the fit, one per (group, phase, intensity bin):
        ``group``, ``phase``, ``signal`` (mean h per ms), ``x_shot``, ``x_read``,
        ``variance`` (of the difference), ``quantisation``, ``n``, ``weight`` (final).
    warnings : list of str
    """

    model: NoiseModel
    gain_e_per_h: float
    read_noise_e: float
    gain_std: float
    read_noise_std: float
    per_channel: dict
    per_group: list
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
            "per_group": self.per_group,
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


def _common_crop(planes: list, shifts: list) -> list:
    """Views of every plane on the region where ``plane_i[y + dy_i, x + dx_i]`` pairs with ``ref[y, x]``."""
    h, w = planes[0].shape
    y0 = max(max(0, -dy) for dy, _ in shifts)
    y1 = min(min(h, h - dy) for dy, _ in shifts)
    x0 = max(max(0, -dx) for _, dx in shifts)
    x1 = min(min(w, w - dx) for _, dx in shifts)
    return [p[y0 + dy: y1 + dy, x0 + dx: x1 + dx] for p, (dy, dx) in zip(planes, shifts)]


def _texture(signal: np.ndarray) -> np.ndarray:
    """Local texture energy of a Bayer plane: 3x3 mean of the squared central-difference gradient.

    What a sub-pixel motion between the shots leaves in their difference is about the shift
    times this gradient, so the flattest pixels by this measure carry the least of it.  It
    is computed from the signal S alone, whose noise is independent of the combination's
    (see :func:`estimate_noise_model`), so selecting on it does not bias the variance.
    """
    s = signal.astype(np.float32)
    gx = cv2.Sobel(s, cv2.CV_32F, 1, 0, ksize=1, scale=0.5)
    gy = cv2.Sobel(s, cv2.CV_32F, 0, 1, ksize=1, scale=0.5)
    return cv2.boxFilter(gx * gx + gy * gy, cv2.CV_32F, (3, 3))


def _group_points(group: BracketGroup, response: CameraResponse, slope: np.ndarray, *, limits, n_bins: int,
                  flat_fraction: float, min_pixels: int, align: bool, highpass: bool, clip: float):
    """Photon-transfer points of one group: per phase and intensity bin (see estimate_noise_model)."""
    ts = [float(t) for t in group.exposures_ms]
    w = group.weights()
    g = response.g
    black, white = response.black_level, response.white_level
    n = len(group.raws)
    ref = (n - 1) // 2
    planes = [[np.ascontiguousarray(raw[i::2, j::2]) for i, j in PHASES] for raw in group.raws]
    shifts = [(0, 0)] * n
    if align:
        # one shift per shot for all phases, from the 2x2-binned exposure-normalised images,
        # clipped to what no shot saturates, so that saturation does not pull the match
        hs = [sum(g[p] for p in pl) / t for pl, t in zip(planes, ts)]
        top = min(float(h.max()) for h in hs)
        hs = [np.minimum(h, top) for h in hs]
        max_shift = min(hs[0].shape) // 4
        shifts = [(0, 0) if k == ref else _align_shift(hs[ref], hs[k], max_shift) for k in range(n)]
    c_shot = sum(wi * wi / t for wi, t in zip(w, ts))
    c_read = sum(wi * wi / (t * t) for wi, t in zip(w, ts))
    if highpass:
        c_read *= float(_HP_SQ.sum())
    t_lo, t_hi = min(ts), max(ts)
    points = []
    for p in range(len(PHASES)):
        dns = _common_crop([pl[p] for pl in planes], shifts)
        us = [g[d] for d in dns]
        signal = sum(us) / sum(ts)  # total signal / total time: uncorrelated with diff (shot noise)
        diff = sum(wi * u / t for wi, u, t in zip(w, us, ts))
        qterm = sum(wi * wi * slope[d] ** 2 / (t * t) for wi, d, t in zip(w, dns, ts)) / 12.0
        lo, hi = limits(t_lo, t_hi)
        usable = (signal >= lo) & (signal <= hi)
        for d in dns:
            usable &= (d > black) & (d < white)
        if highpass:
            diff = cv2.filter2D(diff, cv2.CV_64F, _HP, borderType=cv2.BORDER_REFLECT)
            x_shot = cv2.filter2D(signal, cv2.CV_64F, _HP_SQ, borderType=cv2.BORDER_REFLECT) * c_shot
            qterm = cv2.filter2D(qterm, cv2.CV_64F, _HP_SQ, borderType=cv2.BORDER_REFLECT)
            # every input pixel of the 3x3 support usable; the image border is not
            usable = cv2.erode(usable.astype(np.uint8), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT,
                               borderValue=0).astype(bool)
        else:
            x_shot = signal * c_shot
        if np.count_nonzero(usable) < min_pixels:
            continue
        grad = _texture(signal)
        s, d, xs, gr, qt = signal[usable], diff[usable], x_shot[usable], grad[usable], qterm[usable]
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
            var, m = robust_variance(d[idx], clip)
            if not math.isfinite(var) or m < min_pixels:
                continue
            points.append((p, float(s[idx].mean()), float(xs[idx].mean()), c_read, var, float(qt[idx].mean()), m,
                           float(np.mean(s[idx] ** 2))))
    return points, shifts


def _fit(x_shot, x_read, y, q, n, *, extra=None, huber: float = 3.0, iterations: int = 8):
    """Weighted least squares ``y - q = alpha x_shot + beta x_read (+ extra @ gamma)``; variance weights, Huber.

    Weights ``(n - 1) / (2 pred^2)`` (the variance of a variance estimate from n normal
    values), iterated with the prediction, times Huber weights on the standardised
    residuals.  Returns (alpha, beta, covariance of (alpha, beta), final weights).
    """
    X = np.column_stack([x_shot, x_read] + ([] if extra is None else [extra]))
    scale = np.abs(X).max(axis=0)
    scale[scale == 0] = 1.0
    Xs = X / scale
    target = y - q
    w = np.ones_like(y)
    coef = np.linalg.lstsq(Xs, target, rcond=None)[0]
    hub = np.ones_like(y)
    floor = 0.25 * np.maximum(y, np.max(y) * 1e-12)  # keeps weights bounded when a fit goes astray
    for _ in range(iterations):
        pred = np.maximum(Xs @ coef + q, floor)
        w = (n - 1) / (2 * pred**2)
        res = (target - Xs @ coef) * np.sqrt(w)
        hub = np.minimum(1.0, huber / np.maximum(np.abs(res), 1e-300))
        ww = w * hub
        A = Xs.T @ (Xs * ww[:, None])
        coef = np.linalg.lstsq(A, Xs.T @ (ww * target), rcond=None)[0]
    ww = w * hub
    A = Xs.T @ (Xs * ww[:, None])
    res = (target - Xs @ coef) * np.sqrt(ww)
    dof = max(len(y) - X.shape[1], 1)
    dispersion = max(1.0, float(res @ res) / dof)
    cov = np.linalg.pinv(A) * dispersion
    coef = coef / scale
    cov = cov / np.outer(scale, scale)
    return float(coef[0]), float(coef[1]), cov[:2, :2], ww


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


def _fit_bins(cols: dict, mask=None, *, motion_term: bool):
    """:func:`_fit` on the photon-transfer points ``cols`` (a boolean ``mask`` selects some),
    with one ``S^2`` column per bracket group when ``motion_term``."""
    m = np.ones(cols["n"].size, dtype=bool) if mask is None else mask
    extra = None
    if motion_term:
        grp = cols["group"][m]
        extra = np.column_stack([(grp == k) * cols["signal2"][m] for k in np.unique(grp)])
    return _fit(cols["x_shot"][m], cols["x_read"][m], cols["variance"][m], cols["quantisation"][m], cols["n"][m],
                extra=extra)


def estimate_noise_model(
    groups,
    response: CameraResponse,
    *,
    n_bins: int = 24,
    flat_fraction: float = 0.5,
    align: bool = True,
    highpass: bool = True,
    motion_term: bool = True,
    clip_sigmas: float = 5.0,
    min_pixels: int = 100,
    per_phase: bool = False,
    bayer_pattern: str | None = "RGGB",
    name: str = "in-situ",
) -> NoiseEstimate:
    """Estimate conversion gain and read noise from a recording's own brackets (photon transfer).

    For brackets of one sweep (exposures t_i, shots ~46 ms apart) the exposure-normalised
    images ``g(d_i) / t_i`` agree up to noise, motion and response error (vignetting and
    pixel sensitivity cancel: same pixel).  A zero-sum combination of them (a pair's
    difference, or a triple's middle shot minus the time interpolation of the outer two,
    :class:`BracketGroup`) keeps the noise, whose variance grows with the signal as
    ``1/G`` (shot) over a floor ``r^2/G^2`` (read).

    Parameters
    ----------
    groups : sequence of BracketGroup
        Pairs or triples of brackets (:func:`bracket_groups` makes them from a recording);
        more groups, better estimate.  Triples are the robust choice on moving cameras.
    response : CameraResponse
        The recording's response (g, levels); the gain comes out in electrons per its unit.
    n_bins : int
        Intensity bins per group and Bayer phase (log-spaced in signal).
    flat_fraction : float
        In each bin, keep this fraction of pixels with the smallest relative gradient of
        the (blurred) signal image: motion between the shots moves edges, not flat areas.
    align : bool
        Apply the integer shift (on the Bayer sub-lattice) found by phase correlation of each
        shot with the group's reference (the middle shot, or the first of a pair) before
        combining; an integer shift moves no noise between pixels.
    highpass : bool
        Measure the variance of the combination after the separable second difference
        ``[1, -2, 1] x [1, -2, 1]`` on each Bayer plane (its exact noise gain enters the
        model, Notes): it removes the residue of sub-pixel motion over smooth texture.
    clip_sigmas : float
        Pixels are used only where every shot's expected signal lies this many noise
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
        No groups, a group with other than 2 or 3 shots, invalid exposures or times,
        mismatched shapes, or too few usable pixels to fit.

    Notes
    -----
    Per pixel, with ``u_i = g(d_i)`` (units of h), weights ``w_i`` (sum 0), the signal
    ``S = sum u_i / sum t_i`` (h per ms) and the combination ``D = sum w_i u_i / t_i``:
    ``var(u_i) = (e_i + r^2) / G^2 + g'(d_i)^2 / 12`` with ``e_i = G S t_i``, so

    ``var(D) = (1/G) S sum(w_i^2 / t_i) + (r^2/G^2) sum(w_i^2 / t_i^2) + Q``,
    ``Q = sum(w_i^2 g'(d_i)^2 / t_i^2) / 12``.

    S and D are uncorrelated for shot noise (``cov = (S/G) sum w_i = 0``), so binning by S
    does not bias var(D).  With the high-pass K (noise independent between pixels),
    ``var(K * D) = (K^2 * var(D))``: the shot and quantisation terms are filtered with the
    squared kernel and the read term is multiplied by ``sum K^2 = 36``, so the model stays
    exact.  In each bin (per group and phase): the mean shot and quantisation terms and a
    robust variance of D (sigma clipping at 4 sigma).  Then
    ``var - Q = alpha x_shot + beta x_read`` by weighted least squares with Huber weights
    gives ``G = 1/alpha`` and ``r = sqrt(beta) / alpha``.  Different exposures separate the
    two terms.  The full well is not fitted: it is ``G g(white_level)``, the electrons at
    which the response reaches the white level (:attr:`NoiseEstimate.full_well_e`); the
    fit uses only signals below 90 % of the range, away from any roll-off of the
    variance near saturation.

    Usable pixels: a first pass keeps signals between 2 % and 90 % of the response range
    in every shot, no shot at the black or white level; the second keeps those whose
    expected electrons lie ``clip_sigmas`` standard deviations inside the electrons of the
    first and last decision levels.  A response whose g(black) is above zero (BorealHDR:
    0.17 of 255) clips the darkest electrons to black, so the read-noise regime (e < r^2)
    may be out of reach and r is then identified only by extrapolation: its uncertainty
    says so.
    """
    groups = list(groups)
    if not groups:
        raise NoiseModelError("no bracket groups given")
    if not isinstance(response, CameraResponse):
        raise NoiseModelError(f"response must be an emulator CameraResponse, got {type(response).__name__}")
    for i, gr in enumerate(groups):
        where = f"group {i} ({getattr(gr, 'label', '') or 'unnamed'})"
        if not isinstance(gr, BracketGroup):
            raise NoiseModelError(f"{where}: expected a BracketGroup, got {type(gr).__name__}")
        if len(gr.raws) not in (2, 3) or len(gr.exposures_ms) != len(gr.raws):
            raise NoiseModelError(f"{where}: need 2 or 3 images with one exposure each, got {len(gr.raws)} images "
                                  f"and {len(gr.exposures_ms)} exposures")
        for raw in gr.raws:
            if not isinstance(raw, np.ndarray) or raw.dtype != np.uint16 or raw.ndim != 2:
                raise NoiseModelError(f"{where}: images must be 2-D uint16 Bayer mosaics")
            if raw.shape != gr.raws[0].shape:
                raise NoiseModelError(f"{where}: shapes differ ({raw.shape} vs {gr.raws[0].shape})")
            if int(raw.max()) > response.white_level:
                raise NoiseModelError(f"{where}: DN {int(raw.max())} above the response's white level "
                                      f"{response.white_level}")
        if min(gr.raws[0].shape) < 16:
            raise NoiseModelError(f"{where}: images too small ({gr.raws[0].shape})")
        for t in gr.exposures_ms:
            if not (isinstance(t, (int, float, np.floating, np.integer)) and math.isfinite(t) and t > 0):
                raise NoiseModelError(f"{where}: exposure {t!r} must be finite and > 0 ms")
        if gr.times_s is not None:
            times = np.asarray(gr.times_s, dtype=np.float64)
            if times.shape != (len(gr.raws),) or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
                raise NoiseModelError(f"{where}: times_s must be one finite, increasing instant per image, "
                                      f"got {gr.times_s!r}")
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

    def pass_one(t_lo, t_hi):
        lo = (max(theta_lo, 0.0) + 0.02 * span) / t_lo
        hi = (max(theta_lo, 0.0) + 0.90 * span) / t_hi
        return lo, hi

    def run(limits):
        pts, shifts = [], []
        for i, gr in enumerate(groups):
            g_pts, shift = _group_points(gr, response, slope, limits=limits, n_bins=n_bins,
                                         flat_fraction=flat_fraction, min_pixels=min_pixels, align=align,
                                         highpass=highpass, clip=4.0)
            pts += [(i,) + t for t in g_pts]
            shifts.append(shift)
        if len(pts) < 3:
            raise NoiseModelError(
                f"only {len(pts)} usable intensity bin(s) in {len(groups)} bracket group(s): too few unclipped, "
                f"flat pixels (min_pixels={min_pixels})"
            )
        arr = np.array(pts, dtype=np.float64)
        cols = dict(group=arr[:, 0].astype(int), phase=arr[:, 1].astype(int), signal=arr[:, 2], x_shot=arr[:, 3],
                    x_read=arr[:, 4], variance=arr[:, 5], quantisation=arr[:, 6], n=arr[:, 7], signal2=arr[:, 8])
        return cols, shifts

    cols, _ = run(pass_one)
    alpha, beta, _, _ = _fit_bins(cols, motion_term=motion_term)
    if not alpha > 0:
        raise NoiseModelError(f"first pass found no positive shot-noise slope (alpha = {alpha:.3g}): "
                              "the differences do not grow with the signal")
    gain1 = 1.0 / alpha
    read1 = math.sqrt(beta) / alpha if beta > 0 else 0.0
    e_lo, e_hi = gain1 * theta_lo, gain1 * theta_hi

    def pass_two(t_lo, t_hi):
        # smallest signal s with G s t - c sqrt(G s t + r^2) >= e_lo for the shortest shot,
        # largest with G s t + c sqrt(G s t + r^2) <= e_hi for the longest (solved on a grid)
        c = clip_sigmas
        e = np.geomspace(max(e_lo, 1e-3) + 1e-3, max(e_hi, 1.0), 4096)
        sd = np.sqrt(e + read1**2)
        ok_lo = e - c * sd >= e_lo
        ok_hi = e + c * sd <= e_hi
        if not ok_lo.any() or not ok_hi.any():
            return np.inf, -np.inf
        lo_e = e[np.argmax(ok_lo)]
        hi_e = e[len(e) - 1 - np.argmax(ok_hi[::-1])]
        return lo_e / (gain1 * t_lo), hi_e / (gain1 * t_hi)

    cols, shifts = run(pass_two)
    alpha, beta, cov, weights = _fit_bins(cols, motion_term=motion_term)
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
        a_p, b_p, c_p, _ = _fit_bins(cols, m, motion_term=motion_term)
        gp, rp, sgp, srp = _gain_read(a_p, b_p, c_p)
        per_channel[nm] = {"gain_e_per_h": gp, "read_noise_e": rp, "gain_std": sgp, "read_noise_std": srp,
                           "n_bins": int(np.count_nonzero(m))}
        phase_gain.append(gp if math.isfinite(gp) else gain)
        phase_read.append(rp if math.isfinite(rp) else read)

    per_group = []
    for i, gr in enumerate(groups):
        m = cols["group"] == i
        entry = {"label": gr.label, "exposures_ms": [float(t) for t in gr.exposures_ms],
                 "shift_px": [[2 * a, 2 * b_] for a, b_ in shifts[i]], "n_bins": int(np.count_nonzero(m)),
                 "n_pixels": int(cols["n"][m].sum())}
        if np.count_nonzero(m) >= 3:
            a_i, b_i, c_i, _ = _fit_bins(cols, m, motion_term=motion_term)
            gi, ri, sgi, sri = _gain_read(a_i, b_i, c_i)
            entry.update(gain_e_per_h=gi, read_noise_e=ri, gain_std=sgi, read_noise_std=sri)
        per_group.append(entry)
    spread = {"gain_e_per_h": _percentiles(e.get("gain_e_per_h", float("nan")) for e in per_group),
              "read_noise_e": _percentiles(e.get("read_noise_e", float("nan")) for e in per_group)}

    if per_phase:
        tile = lambda v: ((v[0], v[1]), (v[2], v[3]))  # noqa: E731
        model = NoiseModel(response, tile(phase_gain), tile(phase_read), name)
    else:
        model = NoiseModel(response, gain, read, name)
    return NoiseEstimate(model, gain, read, sg, sr, per_channel, per_group, spread, cols, warnings)


# ---------------------------------------------------------------------------- measured variance ratio
@dataclass(frozen=True)
class VarianceRatio:
    """The result of :func:`noise_variance_ratio`.

    Attributes
    ----------
    median : float
        Median over intensity bins of emulated / live noise variance.
    bins : list of dict
        Per bin: ``dn_lo``, ``dn_hi`` (bin edges of the level image, DN), ``pixels``,
        ``dof`` (degrees of freedom of each variance), ``emulated_var_dn2``,
        ``live_var_dn2``, ``ratio``.
    mode : str
        ``"temporal"`` (stacks of repeats) or ``"spatial"`` (single flat-field images).
    """

    median: float
    bins: list
    mode: str

    @property
    def max_abs_deviation(self) -> float:
        """Largest ``|ratio - 1|`` over the bins."""
        return float(max(abs(b["ratio"] - 1.0) for b in self.bins))

    def to_dict(self) -> dict:
        return {"median": self.median, "max_abs_deviation": self.max_abs_deviation, "mode": self.mode,
                "bins": list(self.bins)}


def _pooled_variance(images: np.ndarray, key: np.ndarray, members: np.ndarray, temporal: bool):
    """(sum of squared deviations, degrees of freedom) over the groups of ``members`` pixels."""
    if temporal:
        x = images[:, members].astype(np.float64)
        ss = float(np.sum((x - x.mean(axis=0)) ** 2))
        return ss, members.size * (images.shape[0] - 1)
    x = images.reshape(-1)[members].astype(np.float64)
    labels, inv = np.unique(key.reshape(-1)[members], return_inverse=True)
    count = np.bincount(inv, minlength=labels.size)
    mean = np.bincount(inv, weights=x, minlength=labels.size) / count
    ss = float(np.sum((x - mean[inv]) ** 2))
    return ss, members.size - labels.size


def noise_variance_ratio(emulated, live, response: CameraResponse, *, levels=None, valid=None, n_bins: int = 16,
                         range_fraction=(0.01, 0.90), min_dof: int = 50) -> VarianceRatio:
    """Median over intensity bins of emulated noise variance / live-capture noise variance (measured).

    Parameters
    ----------
    emulated, live : ndarray, integer (R, H, W) or (H, W)
        Stacks of R >= 2 repeats of a static scene (independent noise each: emulations of
        independent source captures, and live captures at the target exposure), or single
        images of a flat field.  The two may have different R.
    response : CameraResponse
        Gives the black and white levels that bound the bins.
    levels : ndarray (H, W) or None
        The value that bins each pixel, DN: best the noiseless target image (synthetic data);
        None: the mean of the live stack, or for single images one flat field (all equal).
        For single images pixels with equal ``levels`` are one group (a flat patch); the
        variance of a bin pools the deviations from each group's own mean.
    valid : ndarray of bool (H, W) or None
        Pixels to use (e.g. the emulator's validity mask, or sources not clipped).
    n_bins : int
        Log-spaced bins of ``levels`` between ``range_fraction`` of the DN range.
    range_fraction : (float, float)
        The binned span, as fractions of ``white - black`` above black (default 1 % to
        90 %: away from the clipping that shrinks the variance of both).
    min_dof : int
        Bins with fewer degrees of freedom are skipped.

    Returns
    -------
    VarianceRatio
        ``median`` is the figure results.json reports for one emulation mode.

    Raises
    ------
    NoiseModelError
        Shapes that do not match, fewer than 2 repeats, or no bin with enough data.

    Notes
    -----
    Per pixel the temporal variance over the repeats (ddof 1), pooled over the pixels of
    a bin (sum of squares / degrees of freedom), for each of the two stacks; the ratio of
    the pooled variances per bin, then the median over the bins.  Single flat-field images
    pool deviations from each patch's mean instead (a flat field: one patch per level).
    """
    emu = np.asarray(emulated)
    liv = np.asarray(live)
    if emu.ndim != liv.ndim or emu.ndim not in (2, 3) or emu.shape[-2:] != liv.shape[-2:]:
        raise NoiseModelError(f"emulated {emu.shape} and live {liv.shape} must both be (R, H, W) stacks or (H, W) "
                              "images of one size")
    temporal = emu.ndim == 3
    if temporal and min(emu.shape[0], liv.shape[0]) < 2:
        raise NoiseModelError(f"stacks need at least 2 repeats, got {emu.shape[0]} and {liv.shape[0]}")
    shape = emu.shape[-2:]
    if levels is None:
        levels = liv.astype(np.float64).mean(axis=0) if temporal else np.zeros(shape)
        if not temporal:
            valid_all = np.ones(shape, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
            level = float(np.median(liv[valid_all]))
            levels = np.full(shape, level)
    levels = np.asarray(levels, dtype=np.float64)
    if levels.shape != shape:
        raise NoiseModelError(f"levels has shape {levels.shape}, images {shape}")
    ok = np.isfinite(levels)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != shape:
            raise NoiseModelError(f"valid has shape {valid.shape}, images {shape}")
        ok &= valid
    black, white = response.black_level, response.white_level
    lo = black + range_fraction[0] * (white - black)
    hi = black + range_fraction[1] * (white - black)
    edges = np.geomspace(max(lo, 1.0), hi, n_bins + 1)
    which = np.digitize(levels, edges) - 1
    rows = []
    flat_idx = np.flatnonzero(ok & (which >= 0) & (which < n_bins))
    for b in range(n_bins):
        members = flat_idx[which.reshape(-1)[flat_idx] == b]
        if members.size == 0:
            continue
        if temporal:
            emu_ss, emu_dof = _pooled_variance(emu.reshape(emu.shape[0], -1), None, members, True)
            liv_ss, liv_dof = _pooled_variance(liv.reshape(liv.shape[0], -1), None, members, True)
        else:
            emu_ss, emu_dof = _pooled_variance(emu, levels, members, False)
            liv_ss, liv_dof = _pooled_variance(liv, levels, members, False)
        if min(emu_dof, liv_dof) < min_dof or liv_ss <= 0:
            continue
        v_emu, v_liv = emu_ss / emu_dof, liv_ss / liv_dof
        rows.append({"dn_lo": float(edges[b]), "dn_hi": float(edges[b + 1]), "pixels": int(members.size),
                     "dof": int(min(emu_dof, liv_dof)), "emulated_var_dn2": v_emu, "live_var_dn2": v_liv,
                     "ratio": v_emu / v_liv})
    if not rows:
        raise NoiseModelError(f"noise_variance_ratio: no intensity bin with {min_dof} or more degrees of freedom "
                              f"between DN {lo:.0f} and {hi:.0f}")
    return VarianceRatio(float(np.median([r["ratio"] for r in rows])), rows, "temporal" if temporal else "spatial")
