"""Checks of a finished live study's headline, printed from its folder's ``walks.csv`` without writing into it.

* ``exposim validate level-shift OUT``: per headline comparison and metric, omega2, the level shift
  (:func:`validation.live.level_shift.level_shift`), per-scene omega2 and shift, and the
  leave-one-scene-out check of the headline family, as Markdown;
* ``exposim validate monte-carlo OUT [--seeds N] [--resamples A,B]``: the headline's Monte Carlo
  error (:func:`validation.live.monte_carlo.headline_family`,
  :func:`~validation.live.monte_carlo.verdict_stability`), as JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from emulator.cells import format_number
from emulator.io.files import read_results
from validation.live.config import COMPARISONS, HEADLINE_COMPARISONS, HEADLINE_METRICS, LiveError
from validation.live.headline import with_derived
from validation.live.level_shift import LEVEL_MARGIN, SHIFT_METRICS, leave_one_scene_out, level_shift, per_scene
from validation.live.monte_carlo import headline_family, verdict_stability
from validation.live.table_check import read_folder_table
from validation.protocol import Study
from validation.verdicts.agreement import omega2_untruncated
from validation.verdicts.ranking import walk_labels

__all__ = ["LEVEL_SHIFT", "MONTE_CARLO", "level_shift_markdown"]


def _level_shift_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("folder", type=Path, help="a live study folder with walks.csv and results.json")


def level_shift_markdown(tables: dict, walks, methods, seed: int) -> str:
    """Level shifts, per-scene omega2 and the leave-one-scene-out check of a study's tables (walks x methods per
    run and metric, derived metrics included), as Markdown."""
    scenes, seeds = walk_labels(walks)
    lines = []
    for c, label in enumerate(HEADLINE_COMPARISONS):
        ref, other = COMPARISONS[label]
        if ref not in tables or other not in tables:
            continue
        lines += [f"### {label}", "", f"| metric | omega2 | level shift [95 %] | vs +-{LEVEL_MARGIN:.0%} | per scene: "
                  "omega2 / shift |", "| --- | --- | --- | --- | --- |"]
        for i, m in enumerate(HEADLINE_METRICS + ("rpe_trans_pct",)):
            L, E = tables[ref][m], tables[other][m]
            ok = np.all(np.isfinite(L) & np.isfinite(E), axis=1)
            sh = level_shift(L, E, seeds, seed=[seed, 44_004, c, i]) if m in SHIFT_METRICS else None
            ps = per_scene(L, E, scenes)
            shift = "n/a (fixed mean)" if sh is None else (
                f"{format_number(sh['relative'], '+.1%')} [{format_number(sh['relative_ci95'][0], '+.1%')}, {format_number(sh['relative_ci95'][1], '+.1%')}]")
            lines.append(f"| {m} | {float(omega2_untruncated(L[ok], E[ok])):.3g} | {shift} | "
                         f"{'' if sh is None else sh['verdict']} | "
                         + "; ".join(f"{s} {v['omega2_untruncated']:.2g} / {format_number(v['relative_shift'], '+.0%')}"
                                     for s, v in ps.items() if v["omega2_untruncated"] is not None) + " |")
        lines.append("")
    loso = leave_one_scene_out(tables, walks, methods, seed=seed)
    lines += ["### Leave one scene out (headline family, Holm)", "", "| verdict | on all walks | carried by |",
              "| --- | --- | --- |"]
    lines += [f"| {k} | {r['verdict']} | " + (", ".join(f"{s} ({r['without'][s]} without it)" for s in r["carried_by"])
                                              or "no single scene") + " |" for k, r in loso.items()]
    return "\n".join(lines)


def _run_level_shift(args: argparse.Namespace) -> int:
    try:
        walks, methods, tables = read_folder_table(args.folder)
        seed = int(read_results(args.folder / "results.json")["config"]["seed"])
    except (LiveError, OSError, KeyError) as exc:
        print(f"level_shift: {exc}", file=sys.stderr)
        return 1
    print(level_shift_markdown(with_derived(tables), walks, methods, seed))
    return 0


def _monte_carlo_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("folder", help="a live study folder with walks.csv and results.json")
    p.add_argument("--seeds", type=int, default=20, help="bootstrap seeds (default 20: 0..19)")
    p.add_argument("--resamples", default="1000", help="bootstrap resamples, comma-separated (default 1000)")


def _run_monte_carlo(args: argparse.Namespace) -> int:
    try:
        folder = Path(args.folder)
        walks, methods, tables = read_folder_table(folder)
        seed = int(read_results(folder / "results.json")["config"]["seed"])
        own = headline_family(tables, walks, methods, seed=seed)
        print(json.dumps({k: {"verdict": r["verdict"], "verdict_mc": r["verdict_mc"], "adjusted_mc": r["adjusted_mc"]}
                          for k, r in own.items()}, indent=1))
        for b in (int(x) for x in args.resamples.split(",")):
            st = verdict_stability(tables, walks, methods, seeds=range(args.seeds), n_resamples=b)
            print(json.dumps({"n_resamples": b, "changed": {k: st["counts"][k] for k in st["changed"]},
                              "mc_undetermined_on_some_seed": st["mc_undetermined_on_some_seed"]}, indent=1))
    except (LiveError, OSError, ValueError, KeyError) as exc:
        print(f"monte_carlo: {exc}", file=sys.stderr)
        return 1
    return 0


#: ``exposim validate level-shift``.
LEVEL_SHIFT = Study("level-shift", "level shifts, per-scene omega2 and the leave-one-scene-out check of a finished "
                    "live study's headline, printed as Markdown (the folder is not touched)",
                    _level_shift_arguments, _run_level_shift)
#: ``exposim validate monte-carlo``.
MONTE_CARLO = Study("monte-carlo", "the Monte Carlo error of a finished live study's headline verdicts over bootstrap "
                    "seeds, printed as JSON (the folder is not touched)", _monte_carlo_arguments, _run_monte_carlo)
