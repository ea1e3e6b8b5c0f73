"""The unit of an in-situ noise measurement: :class:`BracketGroup` (consecutive brackets of one sweep)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from emulator.noise.model import NoiseModelError
from emulator.response import CameraResponse

__all__ = ["BracketGroup", "checked_groups"]


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


def checked_groups(groups, response: CameraResponse) -> list:
    """``groups`` as a list, each checked (:func:`estimate_noise_model`, Raises)."""
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
    return groups
