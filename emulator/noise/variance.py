"""The measured noise variance ratio of emulated against live images (:func:`noise_variance_ratio`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from emulator.noise.model import NoiseModelError
from emulator.core.response import CameraResponse

__all__ = ["VarianceRatio", "noise_variance_ratio"]

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
