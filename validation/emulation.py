"""Emulation accuracy on exact synthetic ground truth (paper section V-B, Fig. 3).

For each static scene and camera: capture the six brackets once (noisy, as a real sweep,
and noiseless), and at each of N ground-truth exposures (log-spaced 0.02..50 ms) capture
``repeats`` noisy images plus the exact noiseless image.  Every bracket is emulated to
every ground-truth exposure; the bracket selector's choice indexes those results.

Error figures (RMSE in percent of the DN range, :mod:`validation.common`):

``raw``
    noisy emulation against one noisy ground-truth capture (repeat 0), as on a real camera;
``pair``
    the camera's own noise as the paper measures it: the RMSE between consecutive
    captures at the same exposure, ``sqrt(2) sigma``, with ``sigma^2`` the per-pixel
    variance estimated from the consecutive pairs of the repeats
    (:func:`validation.common.pair_noise_map`) averaged over the same pixels as the RMSE;
``sub`` (the headline)
    ``sqrt(max(raw^2 - sigma^2, 0))``: the ground truth's own noise removed.  It is
    independent of the emulated image, so squared errors add and the subtraction is done
    on squares; the result estimates the RMSE of the emulated image against the
    noise-free image (``exact`` checks the estimator).  The bracket's noise, scaled
    through the ratio, stays in: it is part of what the emulator outputs;
``sub_pair``
    ``sqrt(max(raw^2 - pair^2, 0))``: the paper's "error between consecutive images"
    subtracted (in quadrature): the error beyond what a second real capture would show.
    Emulating down from a longer bracket gives an image less noisy than a capture, so
    this clamps to 0 at most exposures and cannot resolve errors below the camera noise;
``sub_linear``
    the paper's words taken literally, ``max(raw - pair, 0)``;
``exact``
    noisy emulation against the exact noiseless ground truth (what ``sub`` estimates);
``clean``
    noiseless mode: noiseless bracket against noiseless ground truth, which isolates the
    emulation error (quantisation and clipping) from sensor noise; it is checked per pixel
    against :func:`validation.common.quantisation_bound`.

Each is computed over the validity mask of the emulated image (``*_valid``), over all
pixels (``*_all``) and over the invalid pixels (``*_invalid``), with the valid fraction.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from emulator.emulate import emulate
from emulator.select import SELECTORS, saturated_fraction
from validation.common import (
    BRACKETS_MS,
    PAPER_MAX_RMSE_PERCENT,
    PAPER_MEDIAN_RMSE_PERCENT,
    RESPONSES,
    STUDY_SCENES,
    Progress,
    ValidationError,
    camera_summary,
    camera_vignetting,
    capture,
    gt_exposures,
    make_camera,
    pair_noise_map,
    seed_for,
    static_radiance,
    study_scene,
    summary_stats,
    to_percent,
)

__all__ = [
    "EmulationConfig",
    "SweepResult",
    "sweep_static",
    "choose_brackets",
    "run_emulation",
    "hard_cases",
    "METRICS",
]

#: Per-(exposure, bracket) error arrays a sweep returns, in DN.
METRICS = (
    "raw_valid", "raw_all", "sigma_valid", "sigma_all", "pair_valid", "pair_all",
    "exact_valid", "exact_all", "exact_invalid", "clean_valid", "clean_all", "clean_invalid",
)
#: Slack of the per-pixel bound check, DN (float rounding of the forward model).
BOUND_TOL_DN = 1e-6
#: Bins of the pixel-value distributions (Fig. 3 right).
HIST_BINS = 64


@dataclass(frozen=True)
class EmulationConfig:
    """Size of the emulation study.

    Attributes
    ----------
    scenes : tuple of str
        Study scene keys (:data:`validation.common.STUDY_SCENES`).
    responses : tuple of str
        Camera response presets, each run with the preset's vignetting.
    vignetting : tuple of float
        Extra vignetting strengths, each run with the first response.
    n_exposures : int
        Ground-truth exposures, log-spaced over ``[lo_ms, hi_ms]``.
    repeats : int
        Noisy captures per ground-truth exposure (noise estimate; >= 2).
    width, height, spp : int
        Render size and samples per pixel of the radiance.
    seed : int
        Base seed of every capture.
    hist_exposures_ms : tuple of float
        Exposures (nearest grid point) whose pixel-value distributions are kept.
    """

    scenes: tuple = tuple(STUDY_SCENES)
    responses: tuple = RESPONSES
    vignetting: tuple = (0.0, 1.0)
    n_exposures: int = 1000
    repeats: int = 25
    width: int = 96
    height: int = 60
    spp: int = 64
    seed: int = 0
    brackets_ms: tuple = BRACKETS_MS
    lo_ms: float = 0.02
    hi_ms: float = 50.0
    selector: str = "higher-no-sat"
    hist_exposures_ms: tuple = (0.05, 0.5, 3.0, 12.0, 45.0)
    hard_cases: bool = True
    cache_dir: str | None = None

    @classmethod
    def quick(cls, **overrides) -> "EmulationConfig":
        """The reduced configuration (tests, --quick): 40 exposures, 5 repeats, 2 scenes, 64x40."""
        base = dict(scenes=("static_lab", "forest_winter"), n_exposures=40, repeats=5, width=64, height=40,
                    spp=16, vignetting=(0.0,))
        base.update(overrides)
        return cls(**base)

    def __post_init__(self) -> None:
        for s in self.scenes:
            study_scene(s)
        for r in self.responses:
            if r not in RESPONSES:
                raise ValidationError(f"unknown camera response {r!r}; choose from {', '.join(RESPONSES)}")
        if not self.scenes or not self.responses:
            raise ValidationError("need at least one scene and one camera response")
        if self.repeats < 2:
            raise ValidationError(f"repeats must be >= 2 to estimate the camera noise, got {self.repeats}")
        if self.selector not in SELECTORS:
            raise ValidationError(f"unknown selector {self.selector!r}; choose from {', '.join(SELECTORS)}")
        for name in ("width", "height", "spp", "n_exposures"):
            v = getattr(self, name)
            if isinstance(v, bool) or int(v) != v or v < 1:
                raise ValidationError(f"{name} must be a positive integer, got {v!r}")

    def cameras(self) -> list[tuple[str, float | None]]:
        """(response, vignetting or None for the preset's) for every camera configuration."""
        out = [(r, None) for r in self.responses]
        out += [(self.responses[0], float(v)) for v in self.vignetting]
        return out

    def n_steps(self) -> int:
        """Progress units: one per scene, camera and ground-truth exposure (+ hard cases)."""
        return len(self.scenes) * (len(self.cameras()) * self.n_exposures + 1) + (
            len(HARD_EXPOSURES_MS) * 2 if self.hard_cases else 0)

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


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
    dn = np.arange(response.white_level + 1, dtype=np.float64)
    top = float(response.white_level)

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
            vf_noisy[i, j] = valid.mean()
            if i in hist_indices:
                hist[i]["emulated"][j] = np.histogram(emu, edges)[0]

            emu_c, valid_c = emulate(br_clean[j], b, t, response, return_mask=True)
            err = np.abs(emu_c.astype(np.float64) - gt_clean)
            c2 = err * err
            metrics["clean_valid"][i, j] = _rmse_masked(c2, valid_c)
            metrics["clean_all"][i, j] = math.sqrt(c2.mean())
            metrics["clean_invalid"][i, j] = _rmse_masked(c2, ~valid_c)
            vf_clean[i, j] = valid_c.mean()
            if valid_c.any():
                # per-DN bound table (see validation.common.quantisation_bound), gathered
                lo = response.forward(k * response.inverse(np.clip(dn - 0.5, 0.0, top)))
                hi = response.forward(k * response.inverse(np.clip(dn + 0.5, 0.0, top)))
                mid = response.forward(k * response.g)
                bound = np.maximum(hi - mid, mid - lo) + 1.0
                excess[i, j] = float((err - bound[br_clean[j]])[valid_c].max())
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


def _selector_series(sweep: SweepResult, idx: np.ndarray, idx_clean: np.ndarray) -> dict:
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


def _stats_block(series: dict) -> dict:
    out = {}
    for key in ("sub_valid", "sub_all", "sub_pair_valid", "sub_pair_all", "sub_linear_valid", "sub_linear_all",
                "raw_valid", "raw_all", "pair_valid", "pair_all",
                "exact_valid", "exact_all", "clean_valid", "clean_all", "valid_fraction"):
        out[key] = summary_stats(series[key])
    excess = [v for v in series["bound_excess_dn"] if v is not None]
    out["max_bound_excess_dn"] = max(excess) if excess else None
    out["bound_ok"] = bool(not excess or max(excess) <= BOUND_TOL_DN)
    return out


# ---------------------------------------------------------------------------------- hard cases
#: Exposures of the extreme-frame checks (the two ends of the range, the bracket ends and one between).
HARD_EXPOSURES_MS = (0.02, 1.0, 5.5, 32.0, 50.0)


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


# ---------------------------------------------------------------------------------- the study
def _nearest_indices(exposures: np.ndarray, wanted) -> list[int]:
    out = []
    for w in wanted:
        i = int(np.argmin(np.abs(np.log(exposures) - math.log(float(w)))))
        if i not in out:
            out.append(i)
    return out


def run_emulation(config: EmulationConfig, *, progress=None, keep_sweeps: bool = False) -> dict:
    """Run the emulation study.

    Returns a dict: ``results`` (JSON-ready: headline figures, per scene and camera
    statistics, per-exposure series, hard cases), ``arrays`` (numpy arrays behind the
    plots, for ``arrays.npz``), ``plots`` (what the report module draws) and, with
    ``keep_sweeps``, the :class:`SweepResult` objects keyed by (scene, camera label).
    """
    import scenes

    tick = Progress(progress)
    exposures = gt_exposures(config.n_exposures, config.lo_ms, config.hi_ms)
    hist_idx = _nearest_indices(exposures, config.hist_exposures_ms)
    cams = config.cameras()
    main_label = _camera_label(*cams[0])

    per = {}  # (scene, label) -> series
    arrays = {"exposures_ms": exposures, "brackets_ms": np.asarray(config.brackets_ms)}
    sweeps = {}
    scene_info = {}
    hard = {}
    for s_i, key in enumerate(config.scenes):
        radiance = static_radiance(key, width=config.width, height=config.height, spp=config.spp,
                                   seed=0, cache_dir=config.cache_dir)
        spec = study_scene(key)
        dr = float(scenes.dynamic_range_db(radiance))
        scene_info[key] = {"scene": spec.scene, "params": dict(spec.params), "lighting": spec.lighting,
                           "dynamic_range_db": dr, "over_100_db": dr > 100.0,
                           "radiance_percentiles": [float(v) for v in np.percentile(
                               scenes.luminance(radiance), [0.1, 50, 99.9])]}
        tick(1)
        for c_i, (resp, vig) in enumerate(cams):
            camera = make_camera(resp, vig, width=config.width, height=config.height)
            label = _camera_label(resp, vig)
            sw = sweep_static(radiance, camera, exposures_ms=exposures, brackets_ms=config.brackets_ms,
                              repeats=config.repeats, seed=seed_for(config.seed, key, label),
                              hist_indices=hist_idx if c_i == 0 else (), progress=tick)
            idx = choose_brackets(sw, config.selector)
            idx_c = choose_brackets(sw, config.selector, clean=True)
            series = _selector_series(sw, idx, idx_c)
            per[(key, label)] = {"series": series, "stats": _stats_block(series),
                                 "camera": camera_summary(camera), "vignetting": camera_vignetting(camera),
                                 "response": resp}
            if c_i == 0:
                tag = f"{key}"
                arrays[f"{tag}/sub_all"] = to_percent(sw.subtracted("all"), sw.white_level, sw.black_level)
                arrays[f"{tag}/sub_valid"] = to_percent(sw.subtracted("valid"), sw.white_level, sw.black_level)
                arrays[f"{tag}/clean_all"] = sw.percent("clean_all")
                arrays[f"{tag}/clean_valid"] = sw.percent("clean_valid")
                arrays[f"{tag}/raw_all"] = sw.percent("raw_all")
                arrays[f"{tag}/pair_all"] = sw.percent("pair_all")
                arrays[f"{tag}/exact_all"] = sw.percent("exact_all")
                arrays[f"{tag}/valid_fraction"] = sw.valid_frac_noisy
                arrays[f"{tag}/selected"] = idx
                arrays[f"{tag}/hist_edges"] = sw.hist_edges
                for h_i, h in sw.hist.items():
                    arrays[f"{tag}/hist{h_i}/gt"] = h["gt"]
                    arrays[f"{tag}/hist{h_i}/emulated"] = h["emulated"]
            if keep_sweeps:
                sweeps[(key, label)] = sw
        if config.hard_cases and s_i == 0:
            hard = hard_cases(radiance, make_camera(*cams[0], width=config.width, height=config.height),
                              seed=seed_for(config.seed, "hard"), progress=tick)

    results = _assemble(config, exposures, hist_idx, per, scene_info, hard, main_label)
    out = {"results": results, "arrays": arrays}
    if keep_sweeps:
        out["sweeps"] = sweeps
    return out


def _camera_label(response: str, vignetting: float | None) -> str:
    return response if vignetting is None else f"{response}+vig{vignetting:g}"


def _pool(per: dict, keys, field_: str) -> list:
    vals = []
    for k in keys:
        vals.extend(per[k]["series"][field_])
    return vals


def _assemble(config, exposures, hist_idx, per, scene_info, hard, main_label) -> dict:
    labels = list(dict.fromkeys(lbl for (_, lbl) in per))
    main_keys = [(s, main_label) for s in config.scenes]
    pooled = {f: summary_stats(_pool(per, main_keys, f)) for f in (
        "sub_valid", "sub_all", "sub_pair_valid", "sub_pair_all", "sub_linear_valid", "sub_linear_all",
        "raw_valid", "raw_all", "pair_valid", "pair_all", "exact_valid",
        "exact_all", "clean_valid", "clean_all", "valid_fraction")}
    by_camera = {}
    for lbl in labels:
        keys = [(s, lbl) for s in config.scenes]
        first = per[keys[0]]
        by_camera[lbl] = {
            "response": first["response"], "vignetting": first["vignetting"],
            "sub_valid": summary_stats(_pool(per, keys, "sub_valid")),
            "sub_all": summary_stats(_pool(per, keys, "sub_all")),
            "clean_valid": summary_stats(_pool(per, keys, "clean_valid")),
            "clean_all": summary_stats(_pool(per, keys, "clean_all")),
            "bound_ok": all(per[k]["stats"]["bound_ok"] for k in keys),
            "selected_bracket_ms_by_scene": {s: per[(s, lbl)]["series"]["bracket_ms"] for s in config.scenes},
        }
    med = [by_camera[lbl]["sub_valid"]["median"] for lbl in labels]
    mx = [by_camera[lbl]["sub_valid"]["max"] for lbl in labels]
    # how often each camera's selector choice equals the main camera's, per scene and exposure
    agree = {}
    for lbl in labels:
        same = [a == b for s in config.scenes for a, b in zip(per[(s, lbl)]["series"]["bracket_ms"],
                                                               per[(s, main_label)]["series"]["bracket_ms"])]
        agree[lbl] = float(np.mean(same))
    per_scene = {}
    for s in config.scenes:
        per_scene[s] = {lbl: per[(s, lbl)]["stats"] for lbl in labels}
        per_scene[s]["info"] = scene_info[s]
    series = {s: {lbl: per[(s, lbl)]["series"] for lbl in labels} for s in config.scenes}
    bound_ok = all(v["bound_ok"] for v in by_camera.values())
    extremes = {}
    for s in config.scenes:
        for lbl in labels:
            ser = per[(s, lbl)]["series"]
            for pos, name in ((0, "shortest"), (-1, "longest")):
                extremes.setdefault(s, {}).setdefault(lbl, {})[name] = {
                    "target_ms": float(exposures[pos]), "bracket_ms": ser["bracket_ms"][pos],
                    "valid_fraction": ser["valid_fraction"][pos], "sub_valid": ser["sub_valid"][pos],
                    "sub_all": ser["sub_all"][pos], "exact_invalid": ser["exact_invalid"][pos],
                    "clean_valid": ser["clean_valid"][pos], "clean_all": ser["clean_all"][pos]}
    return {
        # headline: the selector, noise subtracted, valid pixels, main camera, all scenes and exposures
        "median_rmse_percent": pooled["sub_valid"]["median"],
        "max_rmse_percent": pooled["sub_valid"]["max"],
        "noiseless_max_rmse_percent": pooled["clean_valid"]["max"],
        "noiseless_median_rmse_percent": pooled["clean_valid"]["median"],
        "median_rmse_percent_all_pixels": pooled["sub_all"]["median"],
        "max_rmse_percent_all_pixels": pooled["sub_all"]["max"],
        "noiseless_max_rmse_percent_all_pixels": pooled["clean_all"]["max"],
        "paper": {"median_rmse_percent": PAPER_MEDIAN_RMSE_PERCENT, "max_rmse_percent": PAPER_MAX_RMSE_PERCENT},
        "selector": config.selector,
        "main_camera": main_label,
        "noiseless_within_analytic_bound": bound_ok,
        "pooled": pooled,
        "by_camera": by_camera,
        "camera_spread": {"median_sub_valid_min": min(med), "median_sub_valid_max": max(med),
                          "max_sub_valid_min": min(mx), "max_sub_valid_max": max(mx),
                          "selector_choice_agreement_with_main": agree},
        "per_scene": per_scene,
        "extreme_exposures": extremes,
        "hard_cases": hard,
        "exposures_ms": [float(t) for t in exposures],
        "hist_exposures_ms": [float(exposures[i]) for i in hist_idx],
        "series": series,
        "definitions": {
            "rmse_percent": "100 * RMSE(DN) / (white_level - black_level)",
            "valid": "over the validity mask of the emulated image (emulator.emulate return_mask)",
            "all": "over all pixels",
            "invalid": "over the pixels outside the validity mask",
            "ground_truth": "one noisy capture (repeat 0 of the repeats) at the target exposure",
            "noise_estimator": "per-pixel variance sigma^2 = mean over the consecutive repeat pairs of "
                               "(c[i+1] - c[i])^2 / 2, averaged over the same pixels as the RMSE; "
                               "pair = sqrt(2) sigma, the RMSE between two captures (the paper's camera noise)",
            "sub": "sqrt(max(raw^2 - sigma^2, 0)): the ground truth's noise removed in quadrature; estimates "
                   "'exact' (headline)",
            "sub_pair": "sqrt(max(raw^2 - pair^2, 0)): the paper's 'error between consecutive images' removed in "
                        "quadrature; clamps to 0 wherever the emulated image is less noisy than a capture",
            "sub_linear": "max(raw - pair, 0): the paper's 'subtract this noise' taken literally",
            "exact": "noisy emulation against the exact noiseless ground truth",
            "clean": "noiseless bracket against noiseless ground truth (emulation error only)",
        },
    }
