"""Camera presets: the BorealHDR-like sensor and four response curves, tabulated per DN.

:data:`PRESETS` names them; :func:`preset_fields` gives the :class:`synth.Camera` fields of
one (what :meth:`synth.Camera.preset` builds).  :func:`response_table` is the inverse
response a dataset stores in ``calibration/response.txt`` (what ``Camera.to_dict`` names and
:func:`synth.load_camera` reads back).
"""

from __future__ import annotations

import math

import numpy as np

from emulator.io.pcalib import PCALIB_TABLE_TOP
from emulator.core.response import BOREALHDR_WHITE_LEVEL, CameraResponse
from synth.errors import CameraError
from synth.response_fit import inverse_response_curve

__all__ = [
    "PRESETS",
    "REFERENCE_RADIANCE",
    "BOREALHDR_FOV_X_DEG",
    "preset_fields",
    "response_table",
]

#: Radiance of a white Lambertian surface facing a 1000 W m^-2 sun, W m^-2 sr^-1
#: (``scenes``' ``reference_radiance``); the presets put it at full well at 1 ms.
REFERENCE_RADIANCE = 1000.0 / math.pi
#: Horizontal field of view of the BorealHDR left camera: 2 atan(960 / 1180.805) (fx from
#: ``calibration/september_2023/left.yaml``), degrees.
BOREALHDR_FOV_X_DEG = math.degrees(2.0 * math.atan(960.0 / 1180.80514))


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



def preset_fields(name: str, overrides: dict) -> dict:
    """:class:`synth.Camera` keyword arguments of preset ``name`` with ``overrides`` applied.

    ``black_level`` (in ``overrides``) rebuilds the response so that no light gives DN
    ``black_level``; a ``response`` in ``overrides`` is used as it is.
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
    return fields


def extend_table(g: np.ndarray, top: int) -> np.ndarray:
    """g over DN 0..len-1 extended to 0..top by repeating the last step (strictly increasing)."""
    if g.size > top:
        return g[: top + 1]
    step = g[-1] - g[-2]
    extra = g[-1] + step * np.arange(1, top - g.size + 2, dtype=np.float64)
    return np.concatenate([g, extra])


def response_table(response: CameraResponse, white_level: int) -> np.ndarray:
    """g over DN 0..max(4095, white): what ``emulator.io.borealhdr.sequence_response`` reads back.

    Above the white level the table continues the last step; those DN never occur (the
    camera and the emulator clip at white), so they change no output.
    """
    return extend_table(np.asarray(response.g), max(PCALIB_TABLE_TOP, white_level))
