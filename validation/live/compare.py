"""Live against emulated: exposure trajectories, images, rankings and noise variance.

* :func:`exposure_log2_errors`: ``|log2(emulated_ms / live_ms)|`` per cycle and method;
* :func:`image_errors`: RMSE of the emulated vs the live left image (% of the DN range);
* :func:`kendall_tau`: agreement of two rankings of the methods (Kendall tau-b);
* :func:`measure_noise_variance_ratio`: emulated / live capture noise variance per
  intensity bin, from repeated captures of one rendered frame (the binning and the ratio
  are :func:`emulator.noise.noise_variance_ratio`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from validation.live.config import DARKENING_PAIRS, LiveError

__all__ = ["exposure_log2_errors", "image_errors", "kendall_tau", "measure_noise_variance_ratio", "stats"]

#: Seed-sequence tag of the noise-ratio captures.
_RATIO_TAG = 14_002


def exposure_log2_errors(emulated, live, names) -> dict[str, np.ndarray]:
    """Per method, ``|log2(emulated_ms / live_ms)|`` of the targets of cycles 1.. (cycle 0 is shared)."""
    out = {}
    for name in names:
        e = {cs.cycle: cs.steps[name].target_ms for cs in emulated if name in cs.steps}
        v = {cs.cycle: cs.steps[name].target_ms for cs in live if name in cs.steps}
        common = sorted(set(e) & set(v))[1:]
        out[name] = np.array([abs(math.log2(e[c] / v[c])) for c in common], dtype=np.float64)
    return out


def image_errors(emulated, live, names, sequence, response) -> dict[str, dict]:
    """Per method: RMSE (% of the DN range) of the emulated vs the live left image of each
    cycle, over the emulation's valid pixels, and the valid fraction."""
    from emulator.core.emulate import validity_mask

    white, black = int(sequence.white_level), int(sequence.black_level)
    cycles = {c.index: c for c in sequence.cycles}
    live_by = {cs.cycle: cs for cs in live}
    out = {}
    for name in names:
        rmse, valid = [], []
        for cs in emulated:
            st, lv = cs.steps.get(name), live_by.get(cs.cycle)
            if st is None or lv is None or name not in lv.steps or st.left is None:
                continue
            src = cycles[cs.cycle].frames["left"][st.bracket_ms].load()
            mask = validity_mask(src, st.ratio, response)
            valid.append(float(mask.mean()))
            if mask.any():
                d = st.left[mask].astype(np.float64) - lv.steps[name].left[mask].astype(np.float64)
                rmse.append(100.0 * math.sqrt(float(np.mean(d * d))) / (white - black))
        out[name] = {"rmse_percent": np.array(rmse), "valid_fraction": np.array(valid)}
    return out


def kendall_tau(live: Mapping[str, float], emulated: Mapping[str, float]) -> dict:
    """Kendall tau-b of two rankings of the same methods (:func:`scipy.stats.kendalltau`).

    Methods missing on either side are left out.  When every method ties on either side
    (both sides included) tau-b is undefined (None) and ``note`` says so: two rankings
    that do not order the methods do not agree, they say nothing.  ``discordant`` lists the method pairs
    ordered oppositely; ``tied_on_one_side_only`` counts the pairs tied on one side only (they
    lower tau-b without being discordant).
    """
    from scipy.stats import kendalltau

    names = [m for m in live if m in emulated and live[m] is not None and emulated[m] is not None]
    x = np.array([float(live[m]) for m in names])
    y = np.array([float(emulated[m]) for m in names])
    disc = [(names[i], names[j]) for i in range(len(names)) for j in range(i + 1, len(names))
            if (x[i] - x[j]) * (y[i] - y[j]) < 0]
    ties = sum(1 for i in range(len(names)) for j in range(i + 1, len(names))
               if (x[i] == x[j]) != (y[i] == y[j]))
    res = {"n": len(names), "discordant": [list(p) for p in disc], "tied_on_one_side_only": ties, "tau": None,
           "note": None}
    if len(names) < 2:
        res["note"] = "fewer than two methods with a value"
    elif np.ptp(x) == 0 and np.ptp(y) == 0:
        res["note"] = "every method ties on both sides: no ranking, tau-b undefined (a tie is not agreement)"
    elif np.ptp(x) == 0 or np.ptp(y) == 0:
        res["note"] = f"every method ties on the {'live' if np.ptp(x) == 0 else 'emulated'} side only: tau-b undefined"
    else:
        res["tau"] = float(kendalltau(x, y, variant="b").statistic)
    return res


def measure_noise_variance_ratio(radiance: np.ndarray, camera, response, noise_model, *, repeats: int = 16,
                                 seed: int = 0, pairs=DARKENING_PAIRS, n_bins: int = 16) -> dict:
    """Emulated noise variance over live capture noise variance, per intensity bin (measured).

    For every (source, target) pair (default :data:`~validation.live.config.DARKENING_PAIRS`:
    target < source, where the source is the cleaner one and consistent emulation can match
    the noise; brightening pairs, :data:`~validation.live.config.BRIGHTENING_PAIRS`, measure
    the excess noise it cannot remove): ``repeats`` noisy captures at the source, each
    emulated to the target plainly and noise-consistently, against ``repeats`` live captures
    at the target.  :func:`emulator.noise.noise_variance_ratio` bins the pixels by their
    noiseless target DN (log-spaced bins between 1 % and 90 % of the range, sources
    unclipped, at least 50 pixels a bin) and gives per bin the ratio of the temporal
    variances (ddof 1).  Returns ``{"plain": median over the bins of every pair,
    "consistent": ..., "theory_plain": ..., "bins": [...]}``; ``theory_plain`` is the
    noise library's predicted ratio (:func:`emulator.noise.excess_map`) averaged per bin.
    """
    import synth
    from emulator.core.emulate import emulate
    from emulator.noise import NoiseModelError, noise_variance_ratio

    white, black = camera.white_level, camera.black_level
    if (int(response.white_level), int(response.black_level)) != (int(white), int(black)):
        raise LiveError(f"noise ratio: response levels {response.black_level}..{response.white_level} differ from "
                        f"the camera's {black}..{white}")
    rows = []
    for p, (src_ms, tgt_ms) in enumerate(pairs):
        if not (tgt_ms > 0 and src_ms > 0 and tgt_ms != src_ms):
            raise LiveError(f"noise_variance_ratio: need positive, different exposures, got {src_ms}, {tgt_ms}")
        ss = lambda *k: np.random.SeedSequence([int(seed), _RATIO_TAG, p, *k])  # noqa: E731
        src = [synth.capture(radiance, src_ms, camera, seed=ss(0, r)) for r in range(repeats)]
        live = np.stack([synth.capture(radiance, tgt_ms, camera, seed=ss(1, r)) for r in range(repeats)])
        plain = np.stack([emulate(s, src_ms, tgt_ms, response) for s in src])
        cons = np.stack([emulate(s, src_ms, tgt_ms, response, noise="consistent", noise_model=noise_model,
                                 rng=np.random.default_rng(ss(2, r))) for r, s in enumerate(src)])
        theory_plain = np.mean([emulate(s, src_ms, tgt_ms, response, noise_model=noise_model, return_excess=True)[1]
                                for s in src[:2]], axis=0)
        mean_dn = synth.capture(radiance, tgt_ms, camera, seed=None, noise=False).astype(np.float64)
        src_mean = synth.capture(radiance, src_ms, camera, seed=None, noise=False)
        ok = (src_mean > black) & (src_mean < white)
        # bins of at least 50 pixels, as many degrees of freedom each
        kw = dict(levels=mean_dn, valid=ok, n_bins=n_bins, min_dof=50 * (repeats - 1))
        try:
            vr_plain = noise_variance_ratio(plain, live, response, **kw)
            vr_cons = noise_variance_ratio(cons, live, response, **kw)
        except NoiseModelError:
            continue  # no bin with enough unclipped pixels at this pair
        cons_by_bin = {b["dn_lo"]: b for b in vr_cons.bins}
        for b in vr_plain.bins:
            m = ok & (mean_dn >= b["dn_lo"]) & (mean_dn < b["dn_hi"])
            rows.append({"source_ms": src_ms, "target_ms": tgt_ms, "dn_lo": b["dn_lo"], "dn_hi": b["dn_hi"],
                         "pixels": b["pixels"], "live_var_dn2": b["live_var_dn2"], "plain": b["ratio"],
                         "consistent": cons_by_bin[b["dn_lo"]]["ratio"],
                         "theory_plain": float(theory_plain[m].mean())})
    if not rows:
        raise LiveError("noise_variance_ratio: no intensity bin with enough unclipped pixels")
    return {"plain": float(np.median([r["plain"] for r in rows])),
            "consistent": float(np.median([r["consistent"] for r in rows])),
            "theory_plain": float(np.median([r["theory_plain"] for r in rows])),
            "consistent_max_abs_deviation": float(max(abs(r["consistent"] - 1.0) for r in rows)),
            "repeats": int(repeats), "pairs_ms": [list(p) for p in pairs], "bins": rows}


def stats(a) -> dict:
    """median, max, mean and count of an array (None for an empty one)."""
    a = np.asarray(a, dtype=np.float64)
    if a.size == 0:
        return {"median": None, "max": None, "mean": None, "n": 0}
    return {"median": float(np.median(a)), "max": float(np.max(a)), "mean": float(np.mean(a)), "n": int(a.size)}
