"""``exposim validate own-residuals OUT``: the verdict rule calibrated on the emulator's own residuals
(:mod:`validation.verdicts.own_calibration`), printed for a study folder's ``walks.csv`` without writing into the
folder.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from emulator.errors import ExposimError
from emulator.io.files import read_results
from validation.live.config import COMPARISONS, HEADLINE_COMPARISONS, HEADLINE_METRICS, RESEEDED
from validation.live.headline import with_derived
from validation.live.table_check import read_folder_table
from validation.protocol import Study
from validation.verdict_studies.study_calibration import check_options, emit
from validation.verdicts.own_calibration import (
    DEFINITION,
    RESAMPLES,
    SCENARIOS,
    STUDIES,
    metric_own_calibration,
    own_residuals,
    scenario_rates,
    study_own_calibration,
)

__all__ = ["SCENARIOS", "STUDIES", "RESAMPLES", "DEFINITION", "STUDY", "own_residuals", "scenario_rates",
           "metric_own_calibration", "study_own_calibration", "markdown", "add_arguments", "run"]


def markdown(cal: dict, gaussian: dict | None = None) -> str:
    """The calibration as Markdown tables (one per comparison); ``gaussian``: power.json's ``walks_to_decide``
    (comparison -> metric -> entry), shown beside the walks to decide from the own residuals."""
    lines = []
    for label, c in cal["comparisons"].items():
        if c.get("status") == "not run":
            continue
        lines += [f"### {label}", "", "| metric | seeds | residual SD / live-live | omega2 | perfect: agrees own / "
                  "family | 0.1: agrees own / family | 0.2: agrees / disagrees own | 0.3: disagrees own / family | "
                  "walks to decide (family level) | Gaussian (power.json) |", "|" + " --- |" * 10]
        for metric, r in c["metrics"].items():
            if r.get("status") != "computed":
                lines.append(f"| {metric} | {r.get('seeds_drawn_from')} | {r.get('reason', '')} |||||||")
                continue
            sc = r["scenarios"]
            own, fam = list(next(iter(sc.values())))

            def pct(key, level, verdict):
                return f"{100 * sc[key][level][verdict]:.0f} %"
            ratio = r["residual_sd"].get("ratio")
            wd = r.get("walks_to_decide") or {}
            g = ((gaussian or {}).get(label) or {}).get(metric) or {}
            lines.append(" | ".join([
                f"| {metric}", str(r["seeds_drawn_from"]), "" if ratio is None else f"{ratio:.2f}",
                "undefined" if r["omega2_untruncated"] is None else f"{r['omega2_untruncated']:.3g}",
                f"{pct('omega2 0', own, 'agrees')} / {pct('omega2 0', fam, 'agrees')}",
                f"{pct('omega2 0.1', own, 'agrees')} / {pct('omega2 0.1', fam, 'agrees')}",
                f"{pct('omega2 0.2', own, 'agrees')} / {pct('omega2 0.2', own, 'disagrees')}",
                f"{pct('omega2 0.3', own, 'disagrees')} / {pct('omega2 0.3', fam, 'disagrees')}",
                f"{wd.get('walks') or '> ' + str(wd.get('sizes_tried', [{}])[-1].get('walks'))} ({wd.get('towards')})"
                if wd else "", "" if not g else f"{g.get('walks') or 'none within 240'} ({g.get('towards')})"]) + " |")
        lines.append("")
    return "\n".join(lines)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``exposim validate own-residuals``."""
    p.add_argument("folder", type=Path, help="a live study folder with walks.csv")
    p.add_argument("--studies", type=int, default=STUDIES, help=f"drawn studies per scenario and size "
                   f"(default {STUDIES})")
    p.add_argument("--seed", type=int, default=0, help="seed of the draws (default 0)")
    p.add_argument("--json", type=Path, help="also write the numbers to this new JSON file")


def run(args: argparse.Namespace) -> int:
    """The calibration of a live study folder's headline on its emulator's own residuals, printed (and written to a
    new ``--json`` file); the folder is not touched.  A bad folder or option: one line on stderr, exit code 1."""
    try:
        check_options(args.studies, args.json)
        walks, _, tables = read_folder_table(args.folder)
        tables = with_derived(tables)
        comps = {label: COMPARISONS[label] for label in HEADLINE_COMPARISONS}
        size = len(HEADLINE_METRICS) * sum(1 for r, o in comps.values() if r in tables and o in tables)
        t0 = time.perf_counter()
        cal = study_own_calibration(tables, walks, comparisons=comps, metrics=HEADLINE_METRICS, family_size=size,
                                    reseeded=RESEEDED, n_studies=args.studies, seed=args.seed)
        wall = time.perf_counter() - t0
        power = args.folder / "power.json"
        gaussian = read_results(power).get("walks_to_decide") if power.is_file() else None
    except (ExposimError, OSError, ValueError) as exc:
        print(f"own_residuals: {exc}", file=sys.stderr)
        return 1
    return emit(markdown(cal, gaussian) + f"{len(walks)} walks, {args.studies} drawn studies per scenario and size: "
                f"{wall:.1f} s\n", args.json, cal)


#: ``exposim validate own-residuals``.
STUDY = Study("own-residuals", "how often the live-versus-emulated verdict rule is right when the emulator's own "
              "residuals are the noise, on a finished live study's walks.csv (the folder is not touched)",
              add_arguments, run)
