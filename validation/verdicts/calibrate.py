"""Reproduce the calibration tables of docs/verdicts.md: ``python -m validation.verdicts.calibrate``.

Prints, for simulated metric tables (no renders), the verdict rates of a perfect, a random
and a tied emulator at several study sizes and noise scales, and the AE findings' rates
under interchangeable methods and with a true effect.  ``--seeds`` sets the simulated
studies per cell (the docs used 300 for the verdicts, 200 and 100 for the findings).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from validation.verdicts import NOISE_TO_METHOD_SD
from validation.verdicts.findings import FINDINGS, evaluate, finding_power, simulated_tables
from validation.verdicts.power import verdict_rates
from validation.verdicts.simulate import Scales

__all__ = ["main"]


def _pct(r: dict) -> str:
    return f"agrees {100 * r['agrees']:.0f} %, disagrees {100 * r['disagrees']:.0f} %"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m validation.verdicts.calibrate", description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=300, help="simulated studies per cell (default 300)")
    p.add_argument("--walks", type=lambda s: [int(x) for x in s.split(",")], default=[10, 30, 40, 50, 60],
                   help="study sizes (default 10,30,40,50,60)")
    p.add_argument("--findings", action="store_true", help="also the AE findings' tables (slower)")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    for label, noise in NOISE_TO_METHOD_SD.items():
        sc = Scales(sd_method=1.0, sd_walk_method=0.5, sd_noise=noise)
        for w in args.walks:
            perfect = verdict_rates("live-draw", w, sc, n_seeds=args.seeds, n_resamples=200, seed=[w, 1])
            random = verdict_rates("random", w, sc, n_seeds=args.seeds, n_resamples=200, seed=[w, 2])
            tied = verdict_rates("tied", w, sc, n_seeds=args.seeds, n_resamples=200, seed=[w, 3])
            print(f"{label} scale (noise / method SD {noise}), {w} walks: perfect {_pct(perfect)}; random "
                  f"{_pct(random)}; tied {_pct(tied)}", flush=True)
    if args.findings:
        rng = np.random.default_rng(0)
        for w in (10, 30):
            counts = {fid: 0 for fid in FINDINGS}
            n = max(args.seeds // 2, 1)
            for _ in range(n):
                for r in evaluate(simulated_tables(w, seed=rng), n_resamples=100, seed=rng):
                    if r["id"] in counts and r["verdict"] == "holds":
                        counts[r["id"]] += 1
            print(f"interchangeable methods, {w} walks, {n} studies: largest fraction of a finding holding "
                  f"{max(counts.values()) / n:.3f} ({max(counts, key=counts.get)})", flush=True)
        for d in (0.3, 0.5, 1.0):
            for w in (30, 60, 120):
                pw = finding_power("rpe_trans_worst_kim", d, w, n_seeds=max(args.seeds // 3, 1), seed=[w, 4])
                print(f"rpe_trans_worst_kim, effect {d} noise SD, {w} walks: holds in {100 * pw:.0f} %", flush=True)
    print(f"{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
