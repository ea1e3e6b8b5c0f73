"""What every calibration returns (:class:`CalibrationResult`) and what every estimator shares.

The table's top DN for a white level (:func:`table_top_for`), the Bayer planes of a mosaic
(:func:`bayer_subsample`) and the ``progress(done, total, label)`` convention.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np

from emulator.errors import ResponseError
from emulator.io.pcalib import check_origin
from emulator.core.response import CameraResponse

__all__ = ["CalibrationResult", "Progress", "bayer_subsample", "table_top_for", "origin_warnings", "planes_of",
           "sweep_neighbours", "report_progress"]

Progress = Callable[[int, int, str], None] | None


def report_progress(progress: Progress, done: int, total: int, label: str) -> None:
    """Call ``progress(done, total, label)`` unless ``progress`` is None."""
    if progress is not None:
        progress(done, total, label)


def table_top_for(white_level: int) -> int:
    """Top DN of a response table for this white level: 2**bits - 1 (4095 for 12-bit data)."""
    return (1 << int(white_level).bit_length()) - 1


def planes_of(raw: np.ndarray, stride: int) -> list[np.ndarray]:
    """The four Bayer planes of a mosaic, subsampled by ``stride``, flattened."""
    return [p.reshape(-1) for p in bayer_subsample(raw, stride)]


def sweep_neighbours(sequence, cameras, max_ratio: float, prepare: Callable[[np.ndarray], object],
                     progress: Progress = None, label: str = "pair") -> Iterator[tuple]:
    """Every two consecutive brackets ``a < b`` of one sweep with ``b / a <= max_ratio``.

    Yields ``(cycle, camera, a, b, prepared_a, prepared_b)`` for every cycle and camera, where
    ``prepared_x = prepare(raw image at x ms)``; each image is read and prepared once, and
    only the current sweep's are kept.  ``progress`` hears ``label cam cycle a->b ms`` after
    each pair.
    """
    jobs = []
    for cyc in sequence.cycles:
        for cam in cameras:
            es = sorted(cyc.frames.get(cam, {}))
            jobs.extend((cyc, cam, a, b) for a, b in zip(es[:-1], es[1:]) if b / a <= max_ratio)
    cache: dict = {}
    for k, (cyc, cam, a, b) in enumerate(jobs):
        for key in [key for key in cache if key[0] != cyc.index]:  # only this sweep is needed
            del cache[key]
        for e in (a, b):
            if (cyc.index, cam, e) not in cache:
                cache[(cyc.index, cam, e)] = prepare(cyc.frames[cam][e].load())
        yield cyc, cam, a, b, cache[(cyc.index, cam, a)], cache[(cyc.index, cam, b)]
        report_progress(progress, k + 1, len(jobs), f"{label} {cam} cycle {cyc.index} {a:g}->{b:g} ms")


def origin_warnings(response: CameraResponse, black_level: int, source: str) -> list[str]:
    """A warning when a recovered g is not ~ 0 at the black level (the pcalib reader would refuse it)."""
    try:
        check_origin(response.g, min(int(black_level), response.white_level), source)
    except ResponseError as exc:
        return [f"{exc}; the data do not pin the dark end: extend the exposure range or check the black level"]
    return []


def bayer_subsample(raw: np.ndarray, stride: int = 1) -> list[np.ndarray]:
    """The four Bayer planes of a mosaic, each subsampled by ``stride`` (list of 2-D views)."""
    return [raw[i::2, j::2][::stride, ::stride] for i in (0, 1) for j in (0, 1)]


@dataclass
class CalibrationResult:
    """A recovered inverse response and how well it fits.

    Attributes
    ----------
    response : CameraResponse
        g over DN ``0..table_top`` with g(table_top) = 255 (pcalib units); use
        ``response.with_levels(white_level=...)`` to emulate with the data's clip level.
    knots_dn, knots_g : ndarray, float64, shape (n_knots,)
        The piecewise-linear U: knot positions (DN) and values (pcalib units).
    method : str
        ``"als_engel2016"`` (static stack) or ``"comparametric_grossberg2003"`` (in situ).
    observed_dn : (int, int)
        Lowest and highest DN that carried data; g outside is extrapolated.
    residual_rms_dn, residual_robust_dn : float
        Fit residual in DN (RMS and 1.4826 * MAD).  Stack: observed DN minus f(t * B);
        in situ: matched quantile of the longer bracket minus f(r * g(shorter)).
    residual_rms_percent : float
        ``residual_rms_dn`` in % of the DN range (white - black).  ``residual_rms_pct`` is a
        deprecated alias (attribute, and a second key of :meth:`to_dict`).
    noise_dn : float
        Noise estimated from the images (stack only; NaN otherwise).
    samples_dn, samples_g : ndarray
        A subset of the fitted observations (DN, exposure in pcalib units) for plots.
    info : dict
        Everything else (counts, iterations, settings, notes), JSON-ready.
    """

    response: CameraResponse
    knots_dn: np.ndarray
    knots_g: np.ndarray
    method: str
    observed_dn: tuple[int, int]
    residual_rms_dn: float
    residual_robust_dn: float
    residual_rms_percent: float
    noise_dn: float
    samples_dn: np.ndarray
    samples_g: np.ndarray
    white_level: int
    black_level: int
    info: dict = field(default_factory=dict)

    @property
    def residual_rms_pct(self) -> float:
        """Deprecated alias of :attr:`residual_rms_percent`."""
        return self.residual_rms_percent

    def to_dict(self) -> dict:
        """JSON-ready summary (the knots included, the plot samples not)."""
        return {
            "method": self.method,
            "white_level": self.white_level,
            "black_level": self.black_level,
            "table_top": self.response.white_level,
            "observed_dn": list(self.observed_dn),
            "residual_rms_dn": self.residual_rms_dn,
            "residual_robust_dn": self.residual_robust_dn,
            "residual_rms_percent": self.residual_rms_percent,
            "residual_rms_pct": self.residual_rms_percent,  # deprecated alias of residual_rms_percent
            "noise_dn": None if not math.isfinite(self.noise_dn) else self.noise_dn,
            "knots_dn": self.knots_dn.tolist(),
            "knots_g": self.knots_g.tolist(),
            **self.info,
        }
