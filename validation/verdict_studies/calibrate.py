"""Reproduce the calibration tables of docs/verdicts.md: ``exposim validate verdict-rates``.

Prints, for simulated metric tables (no renders), the verdict rates of a perfect, a random
and a tied emulator and of one whose true omega2 is exactly the margin, at several study
sizes and noise scales, and (``--findings``) how often
each AE finding is judged ``holds`` when its claim is false (tied and near-tied
configurations, Gaussian, one far noisier method, heavy tails) and its power by effect size,
and (``--intervals``) how often each one-sided bound of omega2 lies on the wrong side of a
known true omega2.
``--seeds`` sets the simulated studies per cell.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from emulator.core.stats import percentile_interval, rng_of
from validation.protocol import Study
from validation.verdicts import NOISE_TO_METHOD_SD
from validation.verdicts.agreement import OMEGA2_MAX, omega2_untruncated
from validation.verdicts.findings import FINDINGS, false_holds_rates, finding_power
from validation.verdicts.power import verdict_rates
from validation.verdicts.simulate import Scales, simulate_tables

__all__ = ["STUDY", "add_arguments", "run", "interval_table", "findings_tables"]


def _pct(r: dict) -> str:
    return f"agrees {100 * r['agrees']:.0f} %, disagrees {100 * r['disagrees']:.0f} %"


def interval_table(n_studies: int, n_resamples: int = 400) -> None:
    """How often each one-sided 95 % bound of omega2 lies on the wrong side of the truth (nominal 5 %): plain and
    bias-corrected percentiles of the untruncated statistic, on studies whose true omega2 is exact."""
    rng = rng_of(0)
    for o in (0.0, OMEGA2_MAX, 1.0):
        for noise, w in ((1.0, 30), (1.0, 56), (NOISE_TO_METHOD_SD["rpe"], 56)):
            t = simulate_tables("exact", w, Scales(1.0, 0.5, noise), n_seeds=n_studies, seed=rng, omega2_true=o)
            raw = omega2_untruncated(t["live"], t["emulated"])
            miss = np.zeros(4)
            for k in range(n_studies):
                idx = rng.integers(0, w, (n_resamples, w))
                boot = omega2_untruncated(t["live"][k][idx], t["emulated"][k][idx])
                p_lo, p_hi = percentile_interval(boot, 0.9)
                c_lo, c_hi = percentile_interval(boot, 0.9, estimate=raw[k])
                miss += [p_hi < o, c_hi < o, p_lo > o, c_lo > o]
            print(f"true omega2 {o}, noise / method SD {noise}, {w} walks, {n_studies} studies: upper bound below "
                  f"the truth: plain {100 * miss[0] / n_studies:.1f} %, bias-corrected {100 * miss[1] / n_studies:.1f} "
                  f"%; lower bound above it: plain {100 * miss[2] / n_studies:.1f} %, bias-corrected "
                  f"{100 * miss[3] / n_studies:.1f} %", flush=True)


def findings_tables(n_studies: int, walks=(30, 56)) -> None:
    """The AE findings: false ``holds`` on tied and near-tied configurations, and power by effect size."""
    tested = list(FINDINGS) + ["vo_similar"]
    cases = (("tied", {}), ("near-tied (rival 0.2 SD ahead)", {"delta": 0.2}), ("tied, M_Kim 10x noisier",
             {"noisy": {"kim": 10.0}}), ("tied, t3 noise", {"df": 3.0}))
    for w in walks:
        for label, kw in cases:
            rates = {f: false_holds_rates(f, w, n_studies=n_studies, seed=[w, len(label)], **kw) for f in tested}
            worst = max(rates, key=lambda f: rates[f]["raw"])
            print(f"false claims, {label}, {w} walks, {n_studies} studies: holds at its own 5 % test at most "
                  f"{100 * rates[worst]['raw']:.1f} % ({worst}); with Holm across the family at most "
                  f"{100 * max(r['verdict'] for r in rates.values()):.1f} %", flush=True)
    for fid in ("fixed_most_matches", "rpe_trans_best_50", "rpe_trans_worst_kim", "gradient_ahead_vo"):
        for d in (0.3, 0.41, 0.5, 1.0):
            pw = [finding_power(fid, d, w, n_seeds=n_studies, seed=[w, 4]) for w in (56, 120, 240)]
            print(f"{fid}, true effect {d} noise SD: holds in " + ", ".join(
                f"{100 * p:.0f} % at {w} walks" for p, w in zip(pw, (56, 120, 240))), flush=True)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``exposim validate verdict-rates``."""
    p.add_argument("--seeds", type=int, default=300, help="simulated studies per cell (default 300)")
    p.add_argument("--walks", type=lambda s: [int(x) for x in s.split(",")], default=[10, 30, 56, 120],
                   help="study sizes (default 10,30,56,120)")
    p.add_argument("--findings", action="store_true", help="also the AE findings' tables")
    p.add_argument("--no-agreement", action="store_true", help="skip the live-versus-emulated tables")
    p.add_argument("--intervals", action="store_true", help="also the one-sided bounds' error rates of omega2")


def run(args: argparse.Namespace) -> int:
    """Print the tables the options ask for and the time they took; exit code 0."""
    t0 = time.perf_counter()
    for label, noise in ({} if args.no_agreement else NOISE_TO_METHOD_SD).items():
        sc = Scales(sd_method=1.0, sd_walk_method=0.5, sd_noise=noise)
        for w in args.walks:
            perfect = verdict_rates("live-draw", w, sc, n_seeds=args.seeds, n_resamples=200, seed=[w, 1])
            random = verdict_rates("random", w, sc, n_seeds=args.seeds, n_resamples=200, seed=[w, 2])
            tied = verdict_rates("tied", w, sc, n_seeds=args.seeds, n_resamples=200, seed=[w, 3])
            margin = verdict_rates("exact", w, sc, n_seeds=args.seeds, n_resamples=200, seed=[w, 5],
                                   omega2_true=OMEGA2_MAX)
            print(f"{label} scale (noise / method SD {noise}), {w} walks: perfect {_pct(perfect)}; random "
                  f"{_pct(random)}; tied {_pct(tied)}; true omega2 exactly {OMEGA2_MAX} {_pct(margin)}", flush=True)
    if args.intervals:
        interval_table(args.seeds)
    if args.findings:
        findings_tables(args.seeds)
    print(f"{time.perf_counter() - t0:.0f} s")
    return 0


_HELP = ("the verdict rule's rates on simulated metric tables (no renders): a perfect, a random, a tied emulator and "
         "one at the margin, by study size and noise scale")

#: ``exposim validate verdict-rates``: simulated tables only (the verdict rule's own check, not a study's).
STUDY = Study("verdict-rates", _HELP, add_arguments, run)
