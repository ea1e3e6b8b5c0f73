"""In-situ noise estimate from a recording's own brackets (photon transfer from cross-bracket differences).

:func:`bracket_groups` (:mod:`emulator.noise.groups`) collects pairs or triples of consecutive shots of each sweep;
:func:`estimate_noise_model` fits the conversion gain and read noise from them
(:class:`NoiseEstimate`).  Against synth's known camera the gain error is +3.1 % for a
static scene, -1.1 % at 1.5 px motion per shot and -13.6 % at the worst case (half a Bayer
cell per shot) (tests/emulator/noise/test_noise_insitu.py).  On the real BorealHDR sample the gain comes
out 7.87 +- 0.25 e- per unit of h (full well ~2005 e-) and the read-noise fit is <= 0:
the read noise is not trustworthy in absolute terms there.

:func:`noise_strata` reports the gain per exposure stratum and Bayer phase with a bootstrap
SE over groups (:func:`bootstrap_gain`) beside the formal one; :func:`bracket_groups` keeps
only still groups given the gyro (``motion``, ``max_motion_px``).  On the real sample the
bootstrap SE is 3.8x the formal one and the strata disagree (4-8-16: 9.7 +- 1.9, 8-16-32:
4.8 +- 0.6), still groups included; docs/blur.md discusses it and the full well.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from emulator.noise.groups import BracketGroup, bracket_groups, checked_groups  # re-exported: groups live there
from emulator.noise.model import PHASES, NoiseModel, NoiseModelError
from emulator.noise.photon_transfer import (finite_percentiles, fit_bins, gain_read, group_points, per_group_fits,
                                             per_phase_fits)
from emulator.noise.tables import response_slope
from emulator.core.response import CameraResponse

__all__ = ["BracketGroup", "bracket_groups", "NoiseEstimate", "estimate_noise_model", "bootstrap_gain", "noise_strata"]


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


def _pass_points(groups, response: CameraResponse, slope, limits, *, n_bins, flat_fraction, min_pixels, align,
                 highpass, done: list, progress) -> tuple[dict, list]:
    """One pass of :func:`estimate_noise_model`: the photon-transfer points of every group within ``limits``
    (signal limits per shortest and longest exposure), as columns, and each group's shift; ``done[0]`` counts
    the groups both passes have done, for ``progress``."""
    pts, shifts = [], []
    for i, gr in enumerate(groups):
        g_pts, shift = group_points(gr, response, slope, limits=limits, n_bins=n_bins,
                                     flat_fraction=flat_fraction, min_pixels=min_pixels, align=align,
                                     highpass=highpass, clip=4.0)
        pts += [(i,) + t for t in g_pts]
        shifts.append(shift)
        done[0] += 1
        if progress is not None:
            progress(done[0], 2 * len(groups), f"noise: pass {1 + (done[0] - 1) // len(groups)} {gr.label}")
    if len(pts) < 3:
        raise NoiseModelError(
            f"only {len(pts)} usable intensity bin(s) in {len(groups)} bracket group(s): too few unclipped, "
            f"flat pixels (min_pixels={min_pixels})"
        )
    arr = np.array(pts, dtype=np.float64)
    cols = dict(group=arr[:, 0].astype(int), phase=arr[:, 1].astype(int), signal=arr[:, 2], x_shot=arr[:, 3],
                x_read=arr[:, 4], variance=arr[:, 5], quantisation=arr[:, 6], n=arr[:, 7], signal2=arr[:, 8])
    return cols, shifts


def _pass_two_limits(gain1: float, read1: float, e_lo: float, e_hi: float, clip_sigmas: float):
    """The second pass's signal limits (per shortest and longest exposure) from the first pass's gain and read
    noise: expected electrons ``clip_sigmas`` standard deviations inside those of the clip levels."""

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

    return pass_two


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
    progress=None,
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
    progress : callable(done, total, label), optional
        Called after each group of each of the two passes.

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
    groups = checked_groups(groups, response)
    if not 0 < flat_fraction <= 1:
        raise NoiseModelError(f"flat_fraction must be in (0, 1], got {flat_fraction!r}")
    names = _phase_names(bayer_pattern)
    slope = response_slope(response)
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

    done = [0]
    opts = dict(n_bins=n_bins, flat_fraction=flat_fraction, min_pixels=min_pixels, align=align, highpass=highpass,
                done=done, progress=progress)

    cols, _ = _pass_points(groups, response, slope, pass_one, **opts)
    alpha, beta, _, _ = fit_bins(cols, motion_term=motion_term)
    if not alpha > 0:
        raise NoiseModelError(f"first pass found no positive shot-noise slope (alpha = {alpha:.3g}): "
                              "the differences do not grow with the signal")
    gain1 = 1.0 / alpha
    read1 = math.sqrt(beta) / alpha if beta > 0 else 0.0
    e_lo, e_hi = gain1 * theta_lo, gain1 * theta_hi

    pass_two = _pass_two_limits(gain1, read1, e_lo, e_hi, clip_sigmas)
    cols, shifts = _pass_points(groups, response, slope, pass_two, **opts)
    alpha, beta, cov, weights = fit_bins(cols, motion_term=motion_term)
    gain, read, sg, sr = gain_read(alpha, beta, cov)
    if not math.isfinite(gain):
        raise NoiseModelError(f"no positive shot-noise slope (alpha = {alpha:.3g})")
    if beta <= 0:
        warnings.append(f"read-noise term fitted <= 0 (beta = {beta:.3g}): read noise set to 0; the data do not "
                        "reach the read-noise regime")
    cols["weight"] = weights

    per_channel, phase_gain, phase_read = per_phase_fits(cols, names, gain, read, motion_term)

    per_group = per_group_fits(groups, cols, shifts, motion_term)
    spread = {"gain_e_per_h": finite_percentiles(e.get("gain_e_per_h", float("nan")) for e in per_group),
              "read_noise_e": finite_percentiles(e.get("read_noise_e", float("nan")) for e in per_group)}

    if per_phase:
        tile = lambda v: ((v[0], v[1]), (v[2], v[3]))  # noqa: E731
        model = NoiseModel(response, tile(phase_gain), tile(phase_read), name)
    else:
        model = NoiseModel(response, gain, read, name)
    return NoiseEstimate(model, gain, read, sg, sr, per_channel, per_group, spread, cols, warnings)


# ---------------------------------------------------------------------------- strata and bootstrap
def _resampled(bins: dict, groups: np.ndarray) -> dict:
    """The photon-transfer points of ``groups`` (indices, repeats allowed), each draw its own group."""
    parts = [np.flatnonzero(bins["group"] == g) for g in groups]
    idx = np.concatenate(parts) if parts else np.zeros(0, dtype=int)
    out = {k: np.asarray(v)[idx] for k, v in bins.items() if k != "group"}
    out["group"] = np.concatenate([np.full(p.size, k) for k, p in enumerate(parts)]) if parts else idx
    return out


def _gain_fit(bins: dict, motion_term: bool) -> tuple[float, float]:
    """(gain, formal standard error) of one fit on ``bins``; NaN when it cannot be made."""
    if bins["n"].size < 3:
        return math.nan, math.nan
    try:
        a, b, cov, _ = fit_bins(bins, motion_term=motion_term)
    except np.linalg.LinAlgError:
        return math.nan, math.nan
    gain, _, sg, _ = gain_read(a, b, cov)
    return gain, sg


def bootstrap_gain(bins: dict, groups=None, *, n_boot: int = 400, seed: int = 0, motion_term: bool = True) -> dict:
    """The gain and its formal and bootstrap standard errors over bracket groups.

    Parameters
    ----------
    bins : dict of ndarray
        :attr:`NoiseEstimate.bins` (the photon-transfer points, with their ``group``).
    groups : sequence of int or None
        Group indices to use (default: every group with points).
    n_boot : int
        Bootstrap draws: ``len(groups)`` groups drawn with replacement, refitted.
    seed : int
        Seeds the draws.

    Returns
    -------
    dict
        ``gain_e_per_h``, ``gain_std`` (formal), ``gain_std_bootstrap``, ``bootstrap_ratio``
        (bootstrap over formal), ``gain_p16``/``gain_p84`` of the draws, ``n_groups``.
    """
    groups = np.unique(bins["group"]) if groups is None else np.asarray(list(groups), dtype=int)
    gain, sg = _gain_fit(_resampled(bins, groups), motion_term)
    rng = np.random.default_rng(seed)
    draws = []
    if groups.size >= 2:
        for _ in range(int(n_boot)):
            g, _ = _gain_fit(_resampled(bins, rng.choice(groups, size=groups.size, replace=True)), motion_term)
            if math.isfinite(g) and g > 0:
                draws.append(g)
    d = np.asarray(draws)
    sb = float(d.std(ddof=1)) if d.size >= 2 else math.nan
    return {"gain_e_per_h": gain, "gain_std": sg, "gain_std_bootstrap": sb,
            "bootstrap_ratio": sb / sg if sg and math.isfinite(sg) else math.nan,
            "gain_p16": float(np.percentile(d, 16)) if d.size else math.nan,
            "gain_p84": float(np.percentile(d, 84)) if d.size else math.nan,
            "n_groups": int(groups.size), "n_boot": int(d.size)}


def noise_strata(estimate: NoiseEstimate, *, n_boot: int = 400, seed: int = 0, motion_term: bool = True,
                 bayer_pattern: str | None = "RGGB") -> dict:
    """The gain pooled, per exposure stratum, per Bayer phase and per both, with formal and bootstrap SE.

    Strata are the groups' exposure sets (``"4-8-16"``, ``"8-16-32"`` ...); the bootstrap
    resamples whole groups within the stratum.  Phases refit every group's points of one
    Bayer phase.  A disagreement beyond the standard errors between strata that differ in
    exposure is what motion residue (variance growing with exposure) would produce.
    """
    bins = estimate.bins
    out = {"pooled": bootstrap_gain(bins, n_boot=n_boot, seed=seed, motion_term=motion_term), "exposure": {},
           "phase": {}}
    labels = ["-".join(f"{t:g}" for t in e["exposures_ms"]) for e in estimate.per_group]
    for lab in sorted(set(labels), key=lambda s: [float(x) for x in s.split("-")]):
        idx = [i for i, x in enumerate(labels) if x == lab and np.any(bins["group"] == i)]
        if idx:
            out["exposure"][lab] = bootstrap_gain(bins, idx, n_boot=n_boot, seed=seed, motion_term=motion_term)
    out["phase_exposure"] = {}
    for p, name in enumerate(_phase_names(bayer_pattern)):
        m = bins["phase"] == p
        if m.any():
            sub = {k: np.asarray(v)[m] for k, v in bins.items()}
            out["phase"][name] = bootstrap_gain(sub, n_boot=n_boot, seed=seed, motion_term=motion_term)
            for lab in out["exposure"]:
                idx = [i for i, x in enumerate(labels) if x == lab and np.any(sub["group"] == i)]
                if idx:
                    out["phase_exposure"][f"{name} {lab}"] = bootstrap_gain(sub, idx, n_boot=n_boot, seed=seed,
                                                                            motion_term=motion_term)
    return out
