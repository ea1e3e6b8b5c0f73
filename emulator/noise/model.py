"""The noise model of a camera (:class:`NoiseModel`): conversion gain, read noise, full well, JSON form.

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

:meth:`NoiseModel.to_json` / :meth:`NoiseModel.from_json` are the model's JSON text; the
files are read and written by :mod:`emulator.io.noisemodel`.
"""

from __future__ import annotations

import hashlib
import json
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

import cv2
import numpy as np

from emulator.errors import EmulationError, ExposimError
from emulator.noise.tables import NoiseTables, build_tables, response_slope
from emulator.core.response import CameraResponse

__all__ = ["NoiseModel", "NoiseModelError", "response_fingerprint", "json_safe", "PHASES",
           "NOISE_MODEL_FORMAT", "NOISE_MODEL_VERSION"]

#: The 2x2 Bayer phases (row % 2, column % 2) in raster order.
PHASES = ((0, 0), (0, 1), (1, 0), (1, 1))
#: How many per-ratio noise tables a model keeps.
TABLE_CACHE_SIZE = 32


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
        g, slope = self.response.g, response_slope(self.response)
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
        tables = build_tables(self, k)
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
