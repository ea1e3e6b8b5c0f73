"""The forward camera model: HDR radiance -> raw Bayer DN, as a machine-vision camera does.

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
   :meth:`emulator.response.CameraResponse.forward` evaluates).  ``floor(f(h) + 1/2)``
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
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from emulator.io.pcalib import PCALIB_TABLE_TOP
from emulator.response import BOREALHDR_WHITE_LEVEL, CameraResponse
from synth.errors import CameraError, RadianceError, SynthError
from synth.response_fit import inverse_response_curve

__all__ = [
    "Camera",
    "capture",
    "noise_model_g",
    "PRESETS",
    "BAYER_PATTERNS",
    "VIGNETTING_MODELS",
    "SKEWNESS_LIMIT",
    "check_radiance",
    "mean_electrons",
    "NORMAL_LEVELS",
    "REFERENCE_RADIANCE",
    "BOREALHDR_FOV_X_DEG",
]

#: Shot + read noise is drawn from the Gaussian approximation where its skewness
#: ``e / (e + read_noise_e**2)**1.5`` is at most this; exact Poisson elsewhere.
SKEWNESS_LIMIT = 0.2
#: Number of quantile levels of the fast standard-normal sampler (16 random bits).
NORMAL_LEVELS = 1 << 16
#: Radiance of a white Lambertian surface facing a 1000 W m^-2 sun, W m^-2 sr^-1
#: (``scenes``' ``reference_radiance``); the presets put it at full well at 1 ms.
REFERENCE_RADIANCE = 1000.0 / math.pi
#: Horizontal field of view of the BorealHDR left camera: 2 atan(960 / 1180.805) (fx from
#: ``calibration/september_2023/left.yaml``), degrees.
BOREALHDR_FOV_X_DEG = math.degrees(2.0 * math.atan(960.0 / 1180.80514))

BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
VIGNETTING_MODELS = ("cos4", "poly")
_CHANNEL_INDEX = {"R": 0, "G": 1, "B": 2}

#: Electron means are capped at this many full wells before noise and quantisation: the
#: result is white either way (the truncated Gaussian moves a sample by < 4.4 sigma), and
#: the grid index stays far inside int32 (OpenCV's float -> int32 conversion does not
#: saturate).  The cap is skipped when the brightest radiance cannot reach it.
_ELECTRON_CAP_FULL_WELLS = 2.0
#: Steps of the electron grid of the quantiser's lookup tables over the response range.
_QUANTISER_BINS = 1 << 16
#: Bins within this margin (in bins) of a decision level are resolved exactly on the
#: noiseless path (float rounding of the bin index is far below it).
_QUANTISER_MARGIN_BINS = 0.25
#: Rows per block of the noisy path (its float32 intermediates then stay in the CPU cache).
_BLOCK_ROWS = 32
#: Largest finite float32 / float64 bit patterns of a non-negative number (sign bit clear).
_FINITE_BITS = {np.dtype(np.float32): np.uint32(0x7F7FFFFF), np.dtype(np.float64): np.uint64(0x7FEFFFFFFFFFFFFF)}
_AMBIGUOUS = np.uint16(0x8000)


# ---------------------------------------------------------------------------- helpers
def _positive_int(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise CameraError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def _finite(value, name: str, *, minimum: float | None = None, strict: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CameraError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v) or (minimum is not None and (v <= minimum if strict else v < minimum)):
        bound = "" if minimum is None else f" {'>' if strict else '>='} {minimum:g}"
        raise CameraError(f"{name} must be finite{bound}, got {value!r}")
    return v


def check_exposure_ms(value, name: str = "exposure_ms") -> float:
    """``value`` as a float number of milliseconds, refusing non-finite or non-positive ones."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SynthError(f"{name} must be a number of milliseconds, got {value!r}") from None
    if not (math.isfinite(v) and v > 0.0):
        raise SynthError(f"{name} must be finite and positive (milliseconds), got {value!r}")
    return v


def _extend_table(g: np.ndarray, top: int) -> np.ndarray:
    """g over DN 0..len-1 extended to 0..top by repeating the last step (strictly increasing)."""
    if g.size > top:
        return g[: top + 1]
    step = g[-1] - g[-2]
    extra = g[-1] + step * np.arange(1, top - g.size + 2, dtype=np.float64)
    return np.concatenate([g, extra])


# ---------------------------------------------------------------------------- camera
@dataclass(frozen=True, eq=False)
class Camera:
    """A synthetic machine-vision camera, as data.

    Parameters
    ----------
    name : str
        Label (a preset name or "custom").
    width, height : int
        Image size in pixels (Bayer sites).
    response : CameraResponse or None
        Inverse response g over DN 0..table top; None gives a linear one.  The camera
        keeps ``response.with_levels(white_level, black_level)``, so ``camera.response``
        is ready for :func:`emulator.emulate` (its table then ends at ``white_level``).
    white_level, black_level : int
        Output clip levels, DN.  Pixels at or below black, or at white, are clipped.
    full_well_e : float
        Electrons at which the output reaches ``white_level`` (saturation capacity).
    read_noise_e : float
        Read noise, electrons rms (Gaussian, added once per capture).
    radiance_scale : float
        Electrons per (W m^-2 sr^-1 * ms) on a site of sensitivity 1 with no vignetting.
    sensitivities : 3x3 tuple of float
        Row c (R, G, B site) gives the weights of radiance R, G, B on that site.
    bayer_pattern : str
        Colour of the 2x2 sites in raster order: "RGGB" (BorealHDR), "BGGR", "GRBG", "GBRG".
    vignetting_model : str
        ``"cos4"``: ``V = (1 + (r / f)^2)^(-2 * strength)`` (the cos^4 law, r the distance
        to the principal point and f the focal length, both in pixels).  ``"poly"``:
        ``V = 1 + strength * sum_i c_i rho^(2 i + 2)`` with ``rho = r / r_corner`` and c
        :attr:`vignetting_coeffs`.
    vignetting_strength : float
        Strength >= 0; 0 gives V = 1 everywhere.
    vignetting_coeffs : tuple of float
        Even-polynomial coefficients of the ``"poly"`` model (default ``(-1,)``: a
        fall-off to ``1 - strength`` at the corners).  V must stay positive.
    fov_x_deg : float
        Horizontal field of view, degrees; sets the focal length
        ``f = (width / 2) / tan(fov / 2)`` with the principal point at the image centre
        ``((width - 1) / 2, (height - 1) / 2)`` (OpenCV pixel-centre convention).

    Notes
    -----
    The pipeline from radiance to DN is in the module docstring.  Derived quantities:
    :attr:`focal_length_px`, :attr:`h_per_electron`, :attr:`conversion_gain_e_per_dn`.
    """

    name: str = "custom"
    width: int = 1920
    height: int = 1200
    response: CameraResponse | None = None
    white_level: int = BOREALHDR_WHITE_LEVEL
    black_level: int = 0
    full_well_e: float = 10500.0
    read_noise_e: float = 2.4
    radiance_scale: float = 10500.0 / REFERENCE_RADIANCE
    sensitivities: tuple = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    bayer_pattern: str = "RGGB"
    vignetting_model: str = "cos4"
    vignetting_strength: float = 0.0
    vignetting_coeffs: tuple = (-1.0,)
    fov_x_deg: float = BOREALHDR_FOV_X_DEG
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        put = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 - frozen dataclass
        if not isinstance(self.name, str) or not self.name:
            raise CameraError(f"name must be a non-empty string, got {self.name!r}")
        put("width", _positive_int(self.width, "width"))
        put("height", _positive_int(self.height, "height"))
        white = _positive_int(self.white_level, "white_level")
        if isinstance(self.black_level, bool) or not isinstance(self.black_level, (int, np.integer)):
            raise CameraError(f"black_level must be an integer, got {self.black_level!r}")
        black = int(self.black_level)
        if not 0 <= black < white:
            raise CameraError(f"need 0 <= black_level < white_level, got {black}, {white}")
        put("white_level", white)
        put("black_level", black)
        response = self.response if self.response is not None else CameraResponse.linear(max(white, 1))
        if not isinstance(response, CameraResponse):
            raise CameraError(f"response must be an emulator CameraResponse, got {type(response).__name__}")
        if response.white_level < white:
            raise CameraError(
                f"response table ends at DN {response.white_level}, below white_level {white}"
            )
        if response.white_level != white or response.black_level != black:
            response = response.with_levels(white_level=white, black_level=black)
        put("response", response)
        put("full_well_e", _finite(self.full_well_e, "full_well_e", minimum=0.0, strict=True))
        put("read_noise_e", _finite(self.read_noise_e, "read_noise_e", minimum=0.0))
        put("radiance_scale", _finite(self.radiance_scale, "radiance_scale", minimum=0.0, strict=True))
        s = np.asarray(self.sensitivities, dtype=np.float64) if _is_numeric(self.sensitivities) else None
        if s is None or s.shape != (3, 3) or not np.all(np.isfinite(s)) or np.any(s < 0) or np.any(s.sum(1) <= 0):
            raise CameraError(
                "sensitivities must be a 3x3 matrix of finite non-negative weights (rows R, G, B sites, "
                f"each with a positive sum), got {self.sensitivities!r}"
            )
        put("sensitivities", tuple(tuple(float(v) for v in row) for row in s))
        pattern = str(self.bayer_pattern).upper()
        if pattern not in BAYER_PATTERNS:
            raise CameraError(f"bayer_pattern must be one of {', '.join(BAYER_PATTERNS)}, got {self.bayer_pattern!r}")
        put("bayer_pattern", pattern)
        if self.vignetting_model not in VIGNETTING_MODELS:
            raise CameraError(
                f"vignetting_model must be one of {', '.join(VIGNETTING_MODELS)}, got {self.vignetting_model!r}"
            )
        strength = _finite(self.vignetting_strength, "vignetting_strength", minimum=0.0)
        put("vignetting_strength", strength)
        coeffs = self.vignetting_coeffs
        if not _is_numeric(coeffs) or np.ndim(coeffs) != 1 or not np.all(np.isfinite(coeffs)):
            raise CameraError(f"vignetting_coeffs must be a 1-D sequence of finite numbers, got {coeffs!r}")
        put("vignetting_coeffs", tuple(float(c) for c in coeffs))
        fov = _finite(self.fov_x_deg, "fov_x_deg")
        if not 0.0 < fov < 180.0:
            raise CameraError(f"fov_x_deg must be in (0, 180) degrees, got {self.fov_x_deg!r}")
        put("fov_x_deg", fov)
        if self.vignetting_model == "poly":
            rho = np.linspace(0.0, 1.0, 1001)
            v = self._poly_vignetting(rho)
            if np.any(v <= 0):
                raise CameraError(
                    f"poly vignetting with strength {strength:g} and coeffs {self.vignetting_coeffs} reaches "
                    f"V = {v.min():.3g} <= 0 at rho = {rho[int(np.argmin(v))]:.3f}"
                )

    # ------------------------------------------------------------------ constructors
    @classmethod
    def preset(cls, name: str, **overrides) -> "Camera":
        """A preset camera, with any field overridden.

        Parameters
        ----------
        name : str
            ``"borealhdr"``: modelled on the BorealHDR Basler a2A1920-51gcPRO (1920x1200,
            12-bit, RGGB, white 4094, black 0, inverse response fitted to the real table,
            see :mod:`synth.response_fit`).  ``"linear"``, ``"gamma22"`` (``f(h) ~
            h^(1/2.2)``), ``"s_curve"`` (``f(h) ~ h^p / (h^p + (1 - h)^p)``, p = 1.8): the
            same sensor with other responses, so the emulator meets curves it was not
            tuned to.
        **overrides
            Any :class:`Camera` field (e.g. ``width=64, height=48``).  ``black_level``
            rebuilds the response so that no light gives DN ``black_level``.

        Notes
        -----
        Sensor figures shared by the presets: full well 10500 e-, read noise 2.4 e-
        (the order of the IMX392 class sensor of that camera; not a calibration of it),
        sensitivities diag(0.55, 1, 0.5), cos^4 vignetting at strength 0.5 over the real
        camera's 78.2 degree field of view (0.52 in the corners at full resolution), and
        ``radiance_scale`` such that :data:`REFERENCE_RADIANCE` (white paper facing a
        1000 W m^-2 sun) fills the well of a green site at 1 ms.
        """
        try:
            curve = _PRESET_CURVES[name]
        except (KeyError, TypeError):
            raise CameraError(f"unknown camera preset {name!r}; choose from {', '.join(PRESETS)}") from None
        fields = dict(_PRESET_SENSOR)
        fields["white_level"] = BOREALHDR_WHITE_LEVEL if name == "borealhdr" else PCALIB_TABLE_TOP
        fields.update(overrides)
        if "response" not in overrides:
            fields["response"] = _preset_response(
                name, curve, int(fields["white_level"]), int(fields.get("black_level", 0))
            )
        fields.setdefault("name", name)
        try:
            return cls(**fields)
        except TypeError as exc:
            raise CameraError(f"Camera.preset({name!r}): {exc}") from None

    @classmethod
    def from_dict(cls, data: dict, response: CameraResponse) -> "Camera":
        """Rebuild a camera from :meth:`to_dict` output and its response table."""
        names = {f.name for f in dataclasses.fields(cls) if f.init and f.name != "response"}
        missing = sorted(names - set(data))
        if missing:
            raise CameraError(f"camera description lacks {', '.join(missing)}")
        return cls(response=response, **{k: data[k] for k in names})

    def replace(self, **changes) -> "Camera":
        """A copy with some fields changed (``dataclasses.replace``; validated again)."""
        return dataclasses.replace(self, **changes)

    def saturating_at(self, radiance: float, exposure_ms: float = 1.0) -> "Camera":
        """A copy whose ``radiance_scale`` fills the well with ``radiance`` at ``exposure_ms``.

        ``radiance`` (W m^-2 sr^-1) is a grey RGB radiance seen by the most sensitive
        site at the principal point (V = 1); e.g. ``scene.reference_radiance`` at 1 ms.
        """
        r = _finite(radiance, "radiance", minimum=0.0, strict=True)
        t = check_exposure_ms(exposure_ms)
        gain = max(sum(row) for row in self.sensitivities)
        return self.replace(radiance_scale=self.full_well_e / (r * t * gain))

    # ------------------------------------------------------------------ derived values
    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of a raw image."""
        return (self.height, self.width)

    @property
    def focal_length_px(self) -> float:
        """Focal length in pixels, ``(width / 2) / tan(fov_x / 2)``."""
        return (self.width / 2.0) / math.tan(math.radians(self.fov_x_deg) / 2.0)

    @property
    def principal_point_px(self) -> tuple[float, float]:
        """(cx, cy) = ((width - 1) / 2, (height - 1) / 2), pixels."""
        return ((self.width - 1) / 2.0, (self.height - 1) / 2.0)

    def intrinsics(self) -> np.ndarray:
        """The 3x3 camera matrix K (float64), square pixels, no distortion."""
        f = self.focal_length_px
        cx, cy = self.principal_point_px
        return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])

    @property
    def h_per_electron(self) -> float:
        """Linear exposure (units of g) of one electron: ``g(white_level) / full_well_e``."""
        return float(self.response.g[self.white_level]) / self.full_well_e

    @property
    def conversion_gain_e_per_dn(self) -> float:
        """Electrons per DN of a response linear from black to white: ``full_well / (white - black)``.

        Exact for the ``linear`` preset (``DN = black + e / conversion_gain``); for another
        response it is the mean gain over the range.
        """
        return self.full_well_e / (self.white_level - self.black_level)

    def bayer_channels(self) -> np.ndarray:
        """The 2x2 colour indices (0 = R, 1 = G, 2 = B) of the pattern, int (2, 2)."""
        return np.array([_CHANNEL_INDEX[c] for c in self.bayer_pattern]).reshape(2, 2)

    def _poly_vignetting(self, rho: np.ndarray) -> np.ndarray:
        v = np.ones_like(rho)
        for i, c in enumerate(self.vignetting_coeffs):
            v += self.vignetting_strength * c * rho ** (2 * i + 2)
        return v

    def vignetting_map(self) -> np.ndarray:
        """V(y, x) at every pixel centre, float64 (height, width), read-only, cached."""
        cached = self._cache.get("vignetting")
        if cached is not None:
            return cached
        cx, cy = self.principal_point_px
        y = np.arange(self.height, dtype=np.float64)[:, None] - cy
        x = np.arange(self.width, dtype=np.float64)[None, :] - cx
        r2 = y * y + x * x
        if self.vignetting_strength == 0.0:
            v = np.ones((self.height, self.width))
        elif self.vignetting_model == "cos4":
            v = (1.0 + r2 / self.focal_length_px**2) ** (-2.0 * self.vignetting_strength)
        else:
            v = self._poly_vignetting(np.sqrt(r2 / max(cx * cx + cy * cy, 1e-300)))
        v.setflags(write=False)
        self._cache["vignetting"] = v
        return v

    def to_dict(self) -> dict:
        """JSON-ready description: every field (the response by name) plus derived values."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.init and f.name != "response"}
        out["sensitivities"] = [list(r) for r in self.sensitivities]
        out["vignetting_coeffs"] = list(self.vignetting_coeffs)
        out["response"] = self.response.name
        out["derived"] = {
            "focal_length_px": self.focal_length_px,
            "principal_point_px": list(self.principal_point_px),
            "h_per_electron": self.h_per_electron,
            "conversion_gain_e_per_dn": self.conversion_gain_e_per_dn,
            "exact_poisson_range_e": self.exact_poisson_range_e(),
        }
        return out

    def exact_poisson_range_e(self) -> list[float] | None:
        """Mean electron counts whose shot noise is drawn as exact Poisson, [lo, hi], or None.

        Where the skewness of shot + read noise, ``e / (e + read_noise_e**2)**1.5``, exceeds
        :data:`SKEWNESS_LIMIT`; None when it never does (read noise of about 1.9 e- or more).
        """
        key = "poisson_range"
        if key not in self._cache:
            self._cache[key] = _skewed_range(self.read_noise_e**2, SKEWNESS_LIMIT)
        return self._cache[key]

    # ------------------------------------------------------------------ cached pipeline pieces
    def _mosaic_terms(self, dtype, rgb: bool) -> list:
        """How to turn radiance into mean electrons per ms: [(flat indices or None, weights)], cached.

        For RGB radiance, term j gathers ``radiance.reshape(-1)[indices]`` (one radiance
        channel per site) and multiplies by ``weights = radiance_scale * V * S[c, j]``
        (``dtype``, (H, W)); a sensitivity matrix with one non-zero per row needs one term.
        For per-site radiance there is one term without indices.
        """
        key = ("mosaic", np.dtype(dtype).str, rgb)
        cached = self._cache.get(key)
        if cached is not None:
            return cached
        v = self.vignetting_map() * self.radiance_scale
        if not rgb:
            terms = [(None, v.astype(dtype))]
        else:
            chan = np.tile(self.bayer_channels(), (self.height // 2 + 1, self.width // 2 + 1))
            chan = chan[: self.height, : self.width]
            s = np.asarray(self.sensitivities)
            if np.all(np.count_nonzero(s, axis=1) == 1):  # one radiance channel per site colour
                pick = tuple(int(j) for j in np.argmax(s != 0, axis=1))
                j = np.array(pick)[chan]
                terms = [(self._gather_index(pick), (v * s[chan, j]).astype(dtype))]
            else:
                terms = [(self._gather_index((j, j, j)), (v * s[chan, j]).astype(dtype))
                         for j in range(3) if np.any(s[:, j])]
        for _, w in terms:
            w.setflags(write=False)
        self._cache[key] = terms
        return terms

    def _gather_index(self, pick: tuple[int, int, int]) -> np.ndarray:
        """Flat indices into an (H, W, 3) image of channel ``pick[c]`` at each site of colour c.

        intp (H, W), cached and shared by the float32 and float64 paths.
        """
        key = ("gather", pick)
        cached = self._cache.get(key)
        if cached is None:
            chan = np.tile(self.bayer_channels(), (self.height // 2 + 1, self.width // 2 + 1))
            chan = chan[: self.height, : self.width]
            site = 3 * np.arange(self.height * self.width, dtype=np.intp).reshape(self.height, self.width)
            cached = site + np.array(pick, dtype=np.intp)[chan]
            cached.setflags(write=False)
            self._cache[key] = cached
        return cached

    def _max_site_weight(self, rgb: bool) -> float:
        """Upper bound of mean electrons per ms per unit of radiance over all sites, cached."""
        key = ("max_weight", rgb)
        if key not in self._cache:
            self._cache[key] = float(sum(float(w.max()) for _, w in self._mosaic_terms(np.float32, rgb)))
        return self._cache[key]

    def _quantiser(self) -> "_Quantiser":
        q = self._cache.get("quantiser")
        if q is None:
            q = self._cache["quantiser"] = _Quantiser(self)
        return q


def _is_numeric(value) -> bool:
    try:
        np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return True


# ---------------------------------------------------------------------------- presets
def _s_curve_inverse(u: np.ndarray, p: float = 1.8) -> np.ndarray:
    """Inverse of ``f(h) = h^p / (h^p + (1 - h)^p)``: ``u^(1/p) / (u^(1/p) + (1 - u)^(1/p))``."""
    a = np.power(u, 1.0 / p)
    b = np.power(np.clip(1.0 - u, 0.0, None), 1.0 / p)
    return a / (a + b)


_PRESET_CURVES = {
    "borealhdr": inverse_response_curve,
    "linear": lambda u: u,
    "gamma22": lambda u: np.power(u, 2.2),
    "s_curve": _s_curve_inverse,
}
PRESETS = tuple(_PRESET_CURVES)

_PRESET_SENSOR = dict(
    width=1920,
    height=1200,
    black_level=0,
    full_well_e=10500.0,
    read_noise_e=2.4,
    radiance_scale=10500.0 / REFERENCE_RADIANCE,
    sensitivities=((0.55, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 0.5)),
    bayer_pattern="RGGB",
    vignetting_model="cos4",
    vignetting_strength=0.5,
    vignetting_coeffs=(-1.0,),
    fov_x_deg=BOREALHDR_FOV_X_DEG,
)


def _preset_response(name: str, curve, white: int, black: int) -> CameraResponse:
    """Tabulate a preset curve g(u), u = (DN - black) / (top - black), over DN 0..top.

    ``top`` is the pcalib table top (4095) or the white level if higher.  Below the black
    level the table continues the first step's slope, so g stays strictly increasing and
    g(black) = curve(0) (0 for every preset but the fitted one, whose g(0) is 0.173).
    """
    if not 0 <= black < white:
        raise CameraError(f"need 0 <= black_level < white_level, got {black}, {white}")
    top = max(PCALIB_TABLE_TOP, white)
    dn = np.arange(top + 1, dtype=np.float64)
    g = np.empty(top + 1)
    g[black:] = curve((dn[black:] - black) / (top - black))
    if black > 0:
        step = g[black + 1] - g[black]
        g[:black] = g[black] - step * (black - dn[:black])
    return CameraResponse(g, top, 0, f"synth:{name}").with_levels(white_level=white, black_level=black)


# ---------------------------------------------------------------------------- quantiser
class _Quantiser:
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

    def __init__(self, camera: Camera) -> None:
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


def _skewed_range(read_var: float, limit: float) -> list[float] | None:
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


# ---------------------------------------------------------------------------- capture
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


def _rng(seed) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, np.random.SeedSequence):
        return np.random.default_rng(seed)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SynthError(
            f"seed must be a non-negative integer, a numpy SeedSequence or Generator, got {seed!r}"
        )
    return np.random.default_rng(int(seed))


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


def _noisy_grid_index(e: np.ndarray, camera: Camera, q: _Quantiser, rng: np.random.Generator) -> np.ndarray:
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
    rng = _rng(seed)
    import cv2

    out = np.empty((camera.height, camera.width), dtype=np.uint16)
    radiance = np.ascontiguousarray(radiance, dtype=np.float32)
    clip = peak * camera._max_site_weight(radiance.ndim == 3) * t > cap  # else min() changes nothing
    for start in range(0, camera.height, _BLOCK_ROWS):  # blocks keep the intermediates in cache
        rows = slice(start, start + _BLOCK_ROWS)
        e = _electrons_f32(radiance, camera, rows, t)
        if clip:
            cv2.min(e, cap, e)
        out[rows] = q.grid(_noisy_grid_index(e, camera, q, rng))
    return out


def noise_model_g(camera: Camera) -> tuple[float, float]:
    """Temporal noise of h (units of g): ``var(h) = shot * h + floor``.

    Returns ``(shot, floor)`` with ``shot = h_per_electron`` (g of one electron) and
    ``floor = (read_noise_e * h_per_electron)^2``; quantisation not included.
    """
    k = camera.h_per_electron
    return k, (camera.read_noise_e * k) ** 2
