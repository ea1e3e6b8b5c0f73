"""The synthetic camera as data: sensor figures, response, vignetting and Bayer mosaic.

:class:`Camera` holds and validates the parameters of the forward model and the pieces
that depend only on them (focal length, vignetting map, per-site mosaic weights, the
quantiser of :mod:`synth.sensor`), cached per camera.  The model itself (radiance ->
electrons -> noise -> DN) is described and run in :mod:`synth.imaging`; presets live in
:mod:`synth.presets`.

The black level is part of the response: a preset built with ``black_level=b`` has
g(b) = 0, so no light gives DN b (an offset), and DN at or below b count as clipped.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from emulator.core.response import BOREALHDR_WHITE_LEVEL, CameraResponse
from synth.errors import CameraError, SynthError
from synth.presets import BOREALHDR_FOV_X_DEG, REFERENCE_RADIANCE, preset_fields
from synth.sensor import SKEWNESS_LIMIT, Quantiser, skewed_range

__all__ = [
    "Camera",
    "BAYER_PATTERNS",
    "VIGNETTING_MODELS",
    "REFERENCE_RADIANCE",
    "BOREALHDR_FOV_X_DEG",
    "check_exposure_ms",
]

BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
VIGNETTING_MODELS = ("cos4", "poly")
_CHANNEL_INDEX = {"R": 0, "G": 1, "B": 2}


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
        is ready for :func:`emulator.core.emulate` (its table then ends at ``white_level``).
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

        fields = preset_fields(name, overrides)
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
            self._cache[key] = skewed_range(self.read_noise_e**2, SKEWNESS_LIMIT)
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

    def _quantiser(self) -> "Quantiser":
        q = self._cache.get("quantiser")
        if q is None:
            q = self._cache["quantiser"] = Quantiser(self)
        return q


def _is_numeric(value) -> bool:
    try:
        np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return True
