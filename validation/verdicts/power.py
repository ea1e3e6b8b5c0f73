"""How many walks a verdict needs: verdict rates on simulated tables, the smallest detectable interaction.

Everything here runs :func:`validation.verdicts.agreement.judge` on tables from
:func:`validation.verdicts.simulate.simulate_tables` with the variance components a pilot
measured (:func:`scales_from_tables`), so the study reports, per metric, the omega2 it
can tell from 0 at its size and the walks an ``agrees`` decision needs.
"""

from __future__ import annotations

import numpy as np

from emulator.core.stats import rng_of, variance_components
from validation.verdicts.agreement import ALPHA, OMEGA2_MAX, VERDICTS, judge_batch
from validation.verdicts.simulate import Scales, simulate_tables

__all__ = ["verdict_rates", "scales_from_tables", "smallest_detectable_omega2", "walks_needed", "power_summary"]


def verdict_rates(kind: str, n_walks: int, scales: Scales, *, n_seeds: int = 200, n_resamples: int = 400,
                  seed=0, omega2_true: float = 0.0, n_methods: int = 7, beta=None) -> dict[str, float]:
    """Fraction of ``n_seeds`` simulated studies judged agrees / disagrees / undetermined."""
    rng = rng_of(seed)
    t = simulate_tables(kind, n_walks, scales, n_methods=n_methods, n_seeds=n_seeds, seed=rng,
                        omega2_true=omega2_true, beta=beta)
    v = judge_batch(t["live"], t["emulated"], n_resamples=n_resamples, seed=rng)["verdict"]
    return {name: float(np.mean(v == k)) for k, name in enumerate(VERDICTS)}


def scales_from_tables(live, emulated=None, control=None) -> Scales:
    """Variance components of one metric from a pilot's walks x methods tables.

    ``sd_method`` and the residual of the live table (:func:`emulator.core.stats.variance_components`);
    the run noise from live - control on the same walks (their residual is twice the run
    noise variance: the walk x method part cancels); the walk x method part is the live
    residual less the noise (0 when the noise explains it all); ``sd_walk`` from the
    walk means.  Without a control, all of the live residual counts as noise (the
    conservative choice: it is what the interaction must be told apart from).
    """
    L = np.asarray(live, dtype=np.float64)
    ok = np.all(np.isfinite(L), axis=1)
    if control is not None:
        C = np.asarray(control, dtype=np.float64)
        ok &= np.all(np.isfinite(C), axis=1)
    L = L[ok]
    s_m, resid = variance_components(L)
    if control is not None:
        _, r_lc = variance_components(L - C[ok])
        noise_var = r_lc / 2.0
    else:
        noise_var = resid
    wm_var = max(float(resid) - float(noise_var), 0.0)
    walk_sd = float(np.std(L.mean(axis=1), ddof=1)) if L.shape[0] > 1 else 0.0
    return Scales(sd_method=float(np.sqrt(max(float(s_m), 0.0))), sd_walk_method=float(np.sqrt(wm_var)),
                  sd_noise=float(np.sqrt(max(float(noise_var), 0.0))), sd_walk=walk_sd)


def smallest_detectable_omega2(n_walks: int, scales: Scales, *, power: float = 0.8, n_seeds: int = 100,
                               n_resamples: int = 300, seed=0, grid=(0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 5.0)) -> float | None:
    """Smallest true omega2 (on ``grid``) judged ``disagrees`` in at least ``power`` of the simulated studies
    at ``n_walks`` (None: none on the grid is)."""
    for o in grid:
        r = verdict_rates("scaled", n_walks, scales, n_seeds=n_seeds, n_resamples=n_resamples, seed=seed,
                          omega2_true=o)
        if r["disagrees"] >= power:
            return float(o)
    return None


def walks_needed(scales: Scales, *, power: float = 0.8, n_seeds: int = 100, n_resamples: int = 300, seed=0,
                 candidates=(10, 15, 20, 30, 45, 60, 90, 120, 180, 240)) -> int | None:
    """Fewest walks (on ``candidates``) at which a perfect emulator (one more live draw) is judged
    ``agrees`` in at least ``power`` of the simulated studies (None: not within the candidates)."""
    if scales.sd_method <= 0:
        return None
    for w in candidates:
        r = verdict_rates("live-draw", w, scales, n_seeds=n_seeds, n_resamples=n_resamples, seed=seed)
        if r["agrees"] >= power:
            return int(w)
    return None


def power_summary(n_walks: int, scales: Scales, *, n_seeds: int = 100, seed=0) -> dict:
    """What the study reports per metric: its scales, the smallest detectable omega2 at its size, the
    walks an agreement decision needs, and the rates of the perfect and the random emulator at its size."""
    return {
        "scales": {"sd_method": scales.sd_method, "sd_walk_method": scales.sd_walk_method,
                   "sd_noise": scales.sd_noise, "sd_walk": scales.sd_walk},
        "noise_to_method_sd": (scales.sd_noise / scales.sd_method) if scales.sd_method > 0 else None,
        "n_walks": int(n_walks),
        "smallest_detectable_omega2": smallest_detectable_omega2(n_walks, scales, n_seeds=n_seeds, seed=seed)
        if scales.sd_method > 0 else None,
        "walks_needed_for_agrees": walks_needed(scales, n_seeds=n_seeds, seed=seed),
        "perfect_emulator_rates": verdict_rates("live-draw", n_walks, scales, n_seeds=n_seeds, seed=seed),
        "random_emulator_rates": verdict_rates("random", n_walks, scales, n_seeds=n_seeds, seed=seed),
        "definition": f"simulated studies ({n_seeds} seeds) with the measured variance components; agrees: omega2 "
                      f"one-sided 95 % upper bound <= {OMEGA2_MAX}; power 0.8; level {ALPHA}",
    }
