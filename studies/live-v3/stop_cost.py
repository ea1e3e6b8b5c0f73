"""The stop's compute cost at the study's shape, for planning the stop session; it reads nothing of the study but
its plan (preregistration.json: resamples, metrics).

The per-walk tables are the rehearsal's (``rehearse_stop.sh``'s stopped folder, a tiny study of the same kind),
tiled to the plan's scenes and ``--seeds`` seeds with a seeded jitter, so that the verdicts' arithmetic runs on
tables of the stop's shape.  It times what the stop computes beyond reading records and writing files: the verdicts
with the plasmode calibration and the power analysis (``judge_metrics``), then the final look's checks
(``final_checks``: own-residuals calibration, 20 bootstrap seeds, leave-one-scene-out).  The numbers are wall and
CPU seconds of this process; the stop's redraw check repeats the same work once more.

Usage: .venv/bin/python studies/live-v3/stop_cost.py REHEARSAL_STOPPED_FOLDER PREREG_JSON --seeds 3 6 12
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from validation.verdicts.plasmode import STUDIES
from validation.live.evidence import judge_metrics, parse_walks_table
from validation.live.final_checks import final_checks


def tiled(tables: dict, scenes, n_seeds: int, seed: int = 44) -> tuple[list[str], dict]:
    """Walk names of ``n_seeds`` seeds x ``scenes`` and the tables' rows drawn (per walk, one of the rehearsal's
    walks, the same row in every run) with a small seeded jitter on every finite cell."""
    rng = np.random.default_rng(seed)
    walks = [f"{s}/seed{k}" for k in range(n_seeds) for s in scenes]
    n_rows = len(next(iter(next(iter(tables.values())).values())))
    rows = rng.integers(0, n_rows, size=len(walks))
    out = {}
    for run, per in tables.items():
        out[run] = {}
        for m, t in per.items():
            t = np.asarray(t, dtype=float)[rows]
            scale = np.nanstd(t) if np.isfinite(t).any() else 0.0
            out[run][m] = t + rng.normal(0.0, 0.1 * (scale or 1.0), size=t.shape)
    return walks, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rehearsal", type=Path, help="rehearse_stop.sh's stopped folder (its walks.csv)")
    ap.add_argument("prereg", type=Path, help="the study's preregistration.json (its plan only)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[3, 6, 12])
    a = ap.parse_args()
    plan = json.loads(a.prereg.read_text())
    _, methods, tables0 = parse_walks_table((a.rehearsal / "walks.csv").read_text())
    R = int(plan["bootstrap_resamples"])
    for n in a.seeds:
        walks, tables = tiled(tables0, plan["scenes"], n)
        t0, c0 = time.perf_counter(), time.process_time()
        judge_metrics(tables, methods, seed=0, walks=walks, n_resamples=R, calibration_studies=None,
                      headline_exclusions=plan["excluded_from_headline"], monte_carlo_rule=True)
        t1, c1 = time.perf_counter(), time.process_time()
        final_checks(tables, walks, methods, prereg=plan, seed=0, plasmode_default=STUDIES)
        t2, c2 = time.perf_counter(), time.process_time()
        print(f"{len(walks)} walks ({n} seeds), {R} resamples: verdicts {t1 - t0:.0f} s wall / {c1 - c0:.0f} s CPU; "
              f"final checks {t2 - t1:.0f} s wall / {c2 - c1:.0f} s CPU", flush=True)


if __name__ == "__main__":
    main()
