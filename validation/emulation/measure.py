"""Emulation study measures: the static sweep (every bracket emulated to every exposure), bracket choice, hard cases."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from emulator.core.emulate import emulate
from emulator.core.select import SELECTORS, saturated_fraction
from validation.common import (
    BRACKETS_MS,
    Progress,
    ValidationError,
    capture,
    pair_noise_map,
    seed_for,
    summary_stats,
    to_percent,
)
from validation.emulation.config import BOUND_TOL_DN, HARD_EXPOSURES_MS, HIST_BINS, METRICS

__all__ = ["SweepResult", "sweep_static", "choose_brackets", "hard_cases", "selector_series", "stats_block"]


# ---------------------------------------------------------------------------------- the sweep
@dataclass
class SweepResult:
    """Everything one (scene, camera) sweep measured.  Error arrays are DN, shape (N, B)."""

    exposures_ms: np.ndarray
    brackets_ms: np.ndarray
    white_level: int
    black_level: int
    metrics: dict
    valid_frac_noisy: np.ndarray
    valid_frac_clean: np.ndarray
    bound_excess: np.ndarray  # max over valid pixels of |err| - bound (<= 0 when within the bound)
    bracket_saturation: np.ndarray  # (B,) saturated fraction of the noisy brackets
    bracket_saturation_clean: np.ndarray
    gt_saturation: np.ndarray  # (N,) of the noiseless ground truth
    brackets_noisy: np.ndarray  # (B, H, W) uint16
    brackets_clean: np.ndarray
    hist: dict = field(default_factory=dict)  # exposure index -> {"gt": counts, "emulated": (B, bins)}
    hist_edges: np.ndarray | None = None

    def percent(self, name: str) -> np.ndarray:
        """Metric ``name`` in percent of the DN range (NaN where undefined: empty masks)."""
        return to_percent(self.metrics[name], self.white_level, self.black_level)

    def subtracted(self, region: str = "valid", noise: str = "sigma") -> np.ndarray:
        """Noise-subtracted RMSE in quadrature, DN, (N, B): ``noise`` is "sigma" (headline) or "pair"."""
        raw, sig = self.metrics[f"raw_{region}"], self.metrics[f"{noise}_{region}"]
        return np.sqrt(np.maximum(raw * raw - sig * sig, 0.0))

    def subtracted_linear(self, region: str = "valid") -> np.ndarray:
        """``max(raw - pair, 0)``, DN, (N, B): the paper's phrasing taken literally."""
        return np.maximum(self.metrics[f"raw_{region}"] - self.metrics[f"pair_{region}"], 0.0)


def _rmse_masked(d2: np.ndarray, mask: np.ndarray) -> float:
    n = int(np.count_nonzero(mask))
    return float(np.sqrt(d2[mask].sum() / n)) if n else float("nan")


def _noisy_metrics(metrics: dict, i: int, j: int, emu, valid, gt, gt_clean, var_map) -> None:
    """Exposure ``i``, bracket ``j`` of the noisy emulation's metrics: against the noisy ground truth (with the
    camera noise measured over the same pixels) and against the exact one."""
    inval = ~valid
    d2 = (emu - gt) ** 2
    metrics["raw_valid"][i, j] = _rmse_masked(d2, valid)
    metrics["raw_all"][i, j] = math.sqrt(d2.mean())
    metrics["sigma_valid"][i, j] = math.sqrt(var_map[valid].mean()) if valid.any() else np.nan
    metrics["sigma_all"][i, j] = math.sqrt(var_map.mean())
    # the paper's "error between consecutive images": sqrt(2) sigma over the same pixels
    metrics["pair_valid"][i, j] = math.sqrt(2.0) * metrics["sigma_valid"][i, j]
    metrics["pair_all"][i, j] = math.sqrt(2.0) * metrics["sigma_all"][i, j]
    e2 = (emu - gt_clean) ** 2
    metrics["exact_valid"][i, j] = _rmse_masked(e2, valid)
    metrics["exact_all"][i, j] = math.sqrt(e2.mean())
    metrics["exact_invalid"][i, j] = _rmse_masked(e2, inval)


def _clean_metrics(metrics: dict, i: int, j: int, emu_c, valid_c, gt_clean, bracket_clean, response, k: float
                   ) -> float:
    """Exposure ``i``, bracket ``j`` of the noiseless emulation's metrics; returns the largest excess of its
    error over the per-DN quantisation bound on valid pixels (-inf without one)."""
    err = np.abs(emu_c.astype(np.float64) - gt_clean)
    c2 = err * err
    metrics["clean_valid"][i, j] = _rmse_masked(c2, valid_c)
    metrics["clean_all"][i, j] = math.sqrt(c2.mean())
    metrics["clean_invalid"][i, j] = _rmse_masked(c2, ~valid_c)
    if not valid_c.any():
        return -np.inf
    # per-DN bound table (see validation.common.quantisation_bound), gathered
    dn = np.arange(response.white_level + 1, dtype=np.float64)
    top = float(response.white_level)
    lo = response.forward(k * response.inverse(np.clip(dn - 0.5, 0.0, top)))
    hi = response.forward(k * response.inverse(np.clip(dn + 0.5, 0.0, top)))
    mid = response.forward(k * response.g)
    bound = np.maximum(hi - mid, mid - lo) + 1.0
    return float((err - bound[bracket_clean])[valid_c].max())


def sweep_static(
    radiance: np.ndarray,
    camera,
    *,
    exposures_ms,
    brackets_ms=BRACKETS_MS,
    repeats: int = 25,
    seed: int = 0,
    hist_indices=(),
    progress=None,
) -> SweepResult:
    """Emulate every ground-truth exposure from every bracket of one static scene.

    Parameters
    ----------
    radiance : ndarray, float32 (H, W, 3)
        Scene radiance (W m^-2 sr^-1), passed to ``synth.capture``.
    camera : synth.Camera
        The synthetic camera (response, levels, noise, vignetting).
    exposures_ms : array-like
        Ground-truth exposure times, ms.
    brackets_ms : sequence of float
        Bracket exposures, ms.
    repeats : int
        Noisy captures per ground-truth exposure (>= 2); repeat 0 is the compared ground truth.
    seed : int
        Base seed; every capture's seed derives from it, the role and the indices.
    hist_indices : iterable of int
        Exposure indices whose pixel-value distributions are kept.
    progress : callable or None
        Called with 1 after each ground-truth exposure.

    Returns
    -------
    SweepResult
    """
    if repeats < 2:
        raise ValidationError(f"repeats must be >= 2 to estimate the camera noise, got {repeats}")
    tick = Progress(progress)
    response = camera.response
    white, black = int(camera.white_level), int(camera.black_level)
    if response.white_level < white:
        raise ValidationError(f"camera white_level {white} above its response table top {response.white_level}")
    exposures = np.asarray(exposures_ms, dtype=np.float64)
    brackets = np.asarray(sorted(float(b) for b in brackets_ms), dtype=np.float64)
    n, nb = exposures.size, brackets.size

    br_noisy = np.stack([capture(radiance, b, camera, seed=seed_for(seed, "bracket", j)) for j, b in enumerate(brackets)])
    br_clean = np.stack([capture(radiance, b, camera, seed=0, noise=False) for b in brackets])
    levels = dict(white_level=white, black_level=black)
    sat = np.array([saturated_fraction(b, **levels) for b in br_noisy])
    sat_clean = np.array([saturated_fraction(b, **levels) for b in br_clean])

    metrics = {m: np.full((n, nb), np.nan) for m in METRICS}
    vf_noisy = np.zeros((n, nb))
    vf_clean = np.zeros((n, nb))
    excess = np.full((n, nb), -np.inf)
    gt_sat = np.zeros(n)
    edges = np.linspace(black, white + 1, HIST_BINS + 1)
    hist = {}
    hist_indices = set(int(i) for i in hist_indices)

    for i, t in enumerate(exposures):
        gt_clean = capture(radiance, t, camera, seed=0, noise=False).astype(np.float64)
        reps = [capture(radiance, t, camera, seed=seed_for(seed, "gt", i, r)) for r in range(repeats)]
        var_map = pair_noise_map(reps)
        gt = reps[0].astype(np.float64)
        gt_sat[i] = saturated_fraction(gt_clean, **levels)
        if i in hist_indices:
            hist[i] = {"gt": np.histogram(gt, edges)[0], "gt_clean": np.histogram(gt_clean, edges)[0],
                       "emulated": np.zeros((nb, HIST_BINS), dtype=np.int64)}
        for j, b in enumerate(brackets):
            k = t / b
            emu, valid = emulate(br_noisy[j], b, t, response, return_mask=True)
            emu = emu.astype(np.float64)
            _noisy_metrics(metrics, i, j, emu, valid, gt, gt_clean, var_map)
            vf_noisy[i, j] = valid.mean()
            if i in hist_indices:
                hist[i]["emulated"][j] = np.histogram(emu, edges)[0]

            emu_c, valid_c = emulate(br_clean[j], b, t, response, return_mask=True)
            vf_clean[i, j] = valid_c.mean()
            excess[i, j] = _clean_metrics(metrics, i, j, emu_c, valid_c, gt_clean, br_clean[j], response, k)
        tick(1)

    return SweepResult(exposures_ms=exposures, brackets_ms=brackets, white_level=white, black_level=black,
                       metrics=metrics, valid_frac_noisy=vf_noisy, valid_frac_clean=vf_clean, bound_excess=excess,
                       bracket_saturation=sat, bracket_saturation_clean=sat_clean, gt_saturation=gt_sat,
                       brackets_noisy=br_noisy, brackets_clean=br_clean, hist=hist, hist_edges=edges)


def choose_brackets(sweep: SweepResult, selector: str = "higher-no-sat", *, clean: bool = False) -> np.ndarray:
    """Index of the bracket ``selector`` picks at each ground-truth exposure (int, (N,)).

    The selector sees the saturated fractions of the noisy brackets (of the noiseless ones
    with ``clean=True``), as it would on a real sweep.
    """
    try:
        fn = SELECTORS[selector]
    except KeyError:
        raise ValidationError(f"unknown selector {selector!r}; choose from {', '.join(SELECTORS)}") from None
    sat = sweep.bracket_saturation_clean if clean else sweep.bracket_saturation
    fractions = {float(b): float(s) for b, s in zip(sweep.brackets_ms, sat)}
    index = {float(b): j for j, b in enumerate(sweep.brackets_ms)}
    levels = dict(white_level=sweep.white_level, black_level=sweep.black_level)
    return np.array([index[float(fn(float(t), fractions, **levels))] for t in sweep.exposures_ms], dtype=np.int64)


def _pick(a: np.ndarray, idx: np.ndarray) -> np.ndarray:
    return a[np.arange(a.shape[0]), idx]


def _nan_to_none(a) -> list:
    return [None if not np.isfinite(v) else float(v) for v in np.asarray(a, dtype=np.float64)]


def selector_series(sweep: SweepResult, idx: np.ndarray, idx_clean: np.ndarray) -> dict:
    """Per-exposure percent figures of the selector's choice (lists, None where undefined)."""
    p = lambda a: to_percent(a, sweep.white_level, sweep.black_level)  # noqa: E731
    m = sweep.metrics
    return {
        "bracket_ms": [float(sweep.brackets_ms[j]) for j in idx],
        "ratio": [float(t / sweep.brackets_ms[j]) for t, j in zip(sweep.exposures_ms, idx)],
        "sub_valid": _nan_to_none(p(_pick(sweep.subtracted("valid"), idx))),
        "sub_all": _nan_to_none(p(_pick(sweep.subtracted("all"), idx))),
        "sub_pair_valid": _nan_to_none(p(_pick(sweep.subtracted("valid", "pair"), idx))),
        "sub_pair_all": _nan_to_none(p(_pick(sweep.subtracted("all", "pair"), idx))),
        "sub_linear_valid": _nan_to_none(p(_pick(sweep.subtracted_linear("valid"), idx))),
        "sub_linear_all": _nan_to_none(p(_pick(sweep.subtracted_linear("all"), idx))),
        "raw_valid": _nan_to_none(p(_pick(m["raw_valid"], idx))),
        "raw_all": _nan_to_none(p(_pick(m["raw_all"], idx))),
        "pair_valid": _nan_to_none(p(_pick(m["pair_valid"], idx))),
        "pair_all": _nan_to_none(p(_pick(m["pair_all"], idx))),
        "exact_valid": _nan_to_none(p(_pick(m["exact_valid"], idx))),
        "exact_all": _nan_to_none(p(_pick(m["exact_all"], idx))),
        "exact_invalid": _nan_to_none(p(_pick(m["exact_invalid"], idx))),
        "clean_bracket_ms": [float(sweep.brackets_ms[j]) for j in idx_clean],
        "clean_valid": _nan_to_none(p(_pick(m["clean_valid"], idx_clean))),
        "clean_all": _nan_to_none(p(_pick(m["clean_all"], idx_clean))),
        "valid_fraction": [float(v) for v in _pick(sweep.valid_frac_noisy, idx)],
        "clean_valid_fraction": [float(v) for v in _pick(sweep.valid_frac_clean, idx_clean)],
        "bound_excess_dn": _nan_to_none(_pick(sweep.bound_excess, idx_clean)),
    }


def stats_block(series: dict) -> dict:
    """Summary statistics of each per-exposure series and whether the bound excess stays within tolerance."""
    out = {}
    for key in ("sub_valid", "sub_all", "sub_pair_valid", "sub_pair_all", "sub_linear_valid", "sub_linear_all",
                "raw_valid", "raw_all", "pair_valid", "pair_all",
                "exact_valid", "exact_all", "clean_valid", "clean_all", "valid_fraction"):
        out[key] = summary_stats(series[key])
    excess = [v for v in series["bound_excess_dn"] if v is not None]
    out["max_bound_excess_dn"] = max(excess) if excess else None
    out["bound_ok"] = bool(not excess or max(excess) <= BOUND_TOL_DN)
    return out


def _scale_for(radiance, camera, exposure_ms: float, *, target: str, fraction: float = 0.97) -> float:
    """Smallest (target="white") or largest (target="black") radiance scale, over a log grid,
    at which a noiseless capture at ``exposure_ms`` has ``fraction`` of its pixels clipped."""
    grid = np.geomspace(1.0, 1e7, 43) if target == "white" else np.geomspace(1.0, 1e-7, 43)
    for s in grid:
        raw = capture(radiance * np.float32(s), exposure_ms, camera, seed=0, noise=False)
        clip = raw >= camera.white_level if target == "white" else raw <= camera.black_level
        if clip.mean() >= fraction:
            return float(s)
    return float(grid[-1])


def hard_cases(radiance: np.ndarray, camera, *, seed: int = 0, progress=None) -> dict:
    """Frames that are almost all saturated or almost all black, at the range ends.

    The radiance is scaled until 97 % of the shortest bracket saturates (or 97 % of the
    longest is black); every bracket is then emulated to :data:`HARD_EXPOSURES_MS`.  Errors
    are reported per region (valid mask, invalid rest, all pixels), never NaN: an empty
    region reports None.
    """
    tick = Progress(progress)
    out = {}
    brackets = np.asarray(BRACKETS_MS)
    for case, target, t_ref in (("almost_all_saturated", "white", brackets[0]),
                                ("almost_all_black", "black", brackets[-1])):
        s = _scale_for(radiance, camera, float(t_ref), target=target)
        sw = sweep_static(radiance * np.float32(s), camera, exposures_ms=HARD_EXPOSURES_MS, repeats=3,
                          seed=seed_for(seed, case), progress=tick)
        idx = choose_brackets(sw)
        rows = []
        for i, t in enumerate(sw.exposures_ms):
            j = int(idx[i])
            vals = {name: sw.metrics[name][i, j] for name in METRICS}
            finite_ok = all(np.isfinite(v) or name.endswith(("_valid", "_invalid")) for name, v in vals.items())
            p = lambda v: None if not np.isfinite(v) else float(to_percent(v, sw.white_level, sw.black_level))  # noqa: E731
            rows.append({
                "target_ms": float(t), "bracket_ms": float(sw.brackets_ms[j]),
                "bracket_saturated_fraction": float(sw.bracket_saturation[j]),
                "gt_saturated_fraction": float(sw.gt_saturation[i]),
                "valid_fraction": float(sw.valid_frac_noisy[i, j]),
                "exact_valid_percent": p(vals["exact_valid"]), "exact_invalid_percent": p(vals["exact_invalid"]),
                "exact_all_percent": p(vals["exact_all"]),
                "sub_valid_percent": p(float(sw.subtracted("valid")[i, j])),
                "clean_valid_percent": p(vals["clean_valid"]), "clean_all_percent": p(vals["clean_all"]),
                "all_figures_finite_or_empty_region": bool(finite_ok),
                "bound_ok": bool(not np.isfinite(sw.bound_excess[i, j]) or sw.bound_excess[i, j] <= BOUND_TOL_DN),
            })
        out[case] = {"radiance_scale": s, "bracket_saturated_fraction": [float(v) for v in sw.bracket_saturation],
                     "rows": rows}
    return out
