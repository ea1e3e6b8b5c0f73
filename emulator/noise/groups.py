"""The unit of an in-situ noise measurement: :class:`BracketGroup` (consecutive brackets of one sweep)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["BracketGroup"]


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
