"""What a finished study can decide, from its own walks: ``exposim validate study-power OUT``.

Reads the walks of a live study (``exposim validate live``, one experiment or
``--replicates``) or an AE study (``exposim validate ae-study``) and reports, from the
variance components measured on them (not the pilot's):

* **agreement** (live study only): per metric the scales (method, walk x method and run
  noise SDs: :func:`validation.live.evidence.metric_scales`, the same that results.json's
  ``power`` uses), the smallest omega2 the study detects and the walks an ``agrees``
  decision needs (:func:`validation.verdicts.power.power_summary`);
* **paper-sized findings**: per finding whose effect the paper's numbers give
  (:data:`PAPER_EFFECTS`), that effect moved into the study's units, divided by the
  study's per-walk residual SD of the finding's metric (walk x method part plus run noise:
  what a contrast of method means over walks is told apart from), and the power of a true
  effect of that size at the study's size and the walks 80 % power needs
  (:func:`validation.verdicts.findings.finding_power`, Holm across all findings included).

How the paper's effect is moved into the study's units (:data:`TRANSFER`): RPE scales with
the walk (a 6 m synthetic walk is not a 1 km trajectory), so its effect is taken relative
to the level (paper effect / mean of the paper's reported values, times the study's mean);
success rates are fractions in both, so their effect is taken as it is.  The table also
shows, for comparison only, the other transfer docs/verdicts.md used before: the effect in
the paper's method SDs (over its reported methods) times the study's method SD.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from emulator.cells import format_number
from emulator.core.stats import variance_components
from emulator.errors import ExposimError
from emulator.io.files import read_results, to_jsonable, write_results
from validation.ae_study.config import PAPER
from validation.live.config import METRICS, LiveError, config_from_dict
from validation.live.evidence import metric_scales, walk_values
from validation.protocol import Study
from validation.verdicts.findings import CLAIMED, FINDINGS, finding_power, unit_tables
from validation.verdicts.power import power_summary

__all__ = ["PAPER_EFFECTS", "TRANSFER", "paper_effects", "study_units", "finding_scales", "paper_sized_power",
           "agreement_power", "markdown", "STUDY", "add_arguments", "run"]

#: Findings' metrics -> (the paper's numbers in validation.ae_study.config.PAPER, how the effect moves to the
#: study's units: "relative" to the level, or "absolute"; scale of the paper's figure to the study's unit).
TRANSFER = {
    "rpe_trans": ("rpe_trans_pct", "relative", 1.0),
    "rpe_rot": ("rpe_rot_deg_per_m", "relative", 1.0),
    "success_seq_hi": ("success_rate_tau100_pct", "absolute", 0.01),
}


def paper_effects() -> dict[str, dict]:
    """Per tested finding whose effect the paper's numbers give: the effect on the paper's reported methods
    (the finding's own statistic, :data:`validation.verdicts.findings.FINDINGS`), their mean (the level),
    and how it moves to the study's units."""
    out = {}
    for fid, (metric, f, definition) in FINDINGS.items():
        if metric not in TRANSFER:
            continue
        key, how, unit = TRANSFER[metric]
        reported = PAPER[key]
        methods = list(reported)
        if any(m not in reported for m in CLAIMED[fid]) or len(methods) <= len(CLAIMED[fid]):
            continue  # the paper gives no number for a claimed method, or none for the others
        values = np.array([reported[m] for m in methods], dtype=np.float64) * unit
        effect = float(f(values, methods))
        out[fid] = {"metric": metric, "paper_effect": effect, "paper_level": float(values.mean()),
                    "paper_method_sd": float(values.std(ddof=1)),
                    "paper_methods": methods, "transfer": how, "definition": definition}
    return out


#: :func:`paper_effects`, computed once.
PAPER_EFFECTS = paper_effects()


def _records(folder: Path, name: str) -> list[dict]:
    one = folder / name
    if one.is_file():
        return [read_results(one)]
    reps = folder / "replicates"
    found = sorted(p / name for p in reps.glob("seed*") if (p / name).is_file()) if reps.is_dir() else []
    return [read_results(p) for p in found]


def study_units(folder, run: str = "emulated-plain") -> tuple[str, list[dict]]:
    """(kind, per-walk summaries ``{method: per-scene entry}``) of a study folder: a live study's run ``run``
    (raw.json of the experiment or of each replicate) or an AE study's walks (results.json ``summary``)."""
    folder = Path(folder)
    raws = _records(folder, "raw.json")
    if raws:
        units = []
        for rec in raws:
            summ = (rec.get("summaries") or {}).get(run)
            if summ is None:
                raise LiveError(f"{folder}: run {run!r} not in this live study (runs: "
                                f"{', '.join(rec.get('summaries') or {}) or 'none'})")
            units += [summ["per_scene"][s] for s in rec["config"]["scenes"] if s in summ["per_scene"]]
        return "live", units
    studies = [r for r in _records(folder, "results.json") if "summary" in r]
    if not studies:
        raise LiveError(f"{folder}: neither a live study (raw.json) nor an AE study (results.json with a summary)")
    return "ae-study", [rows for st in studies for rows in st["summary"]["per_scene"].values()]


def finding_scales(table) -> dict:
    """Level (mean), method SD and per-walk residual SD (walk x method part and run noise, two-way
    decomposition) of one finding metric's (walks, methods) table, over the walks with every method."""
    t = np.asarray(table, dtype=np.float64)
    t = t[np.all(np.isfinite(t), axis=1)]
    if t.shape[0] < 2:
        return {"n_walks": int(t.shape[0]), "level": None, "sd_method": None, "sd_residual": None}
    s_m, resid = variance_components(t)
    return {"n_walks": int(t.shape[0]), "level": float(t.mean()), "sd_method": float(np.sqrt(max(float(s_m), 0.0))),
            "sd_residual": float(np.sqrt(max(float(resid), 0.0)))}


def paper_sized_power(units: list[dict], *, n_walks: int | None = None, n_seeds: int = 100, seed: int = 0,
                      candidates=(10, 20, 30, 45, 60, 90, 120, 180, 240)) -> dict:
    """Per finding of :data:`PAPER_EFFECTS`: the paper's effect in the study's units and in its per-walk
    residual SDs, the power of a true effect of that size at ``n_walks`` (default: the study's complete
    walks) and the fewest ``candidates`` walks with power >= 0.8 (None: not within them)."""
    tables = unit_tables(units)
    out = {}
    for k, (fid, pe) in enumerate(PAPER_EFFECTS.items()):
        sc = finding_scales(tables[pe["metric"]])
        row = {**pe, **sc, "effect_study_units": None, "effect_noise_sd": None, "effect_noise_sd_by_method_sd": None,
               "power_at_size": None,
               "walks_for_80_percent": None}
        if not sc["sd_residual"]:
            row["reason"] = (f"{sc['n_walks']} walk(s) with a {pe['metric']} value for every method: "
                             + ("too few for a residual" if sc["n_walks"] < 2 else "no spread (every value alike)"))
            out[fid] = row
            continue
        eff = pe["paper_effect"] * (sc["level"] / pe["paper_level"] if pe["transfer"] == "relative" else 1.0)
        d = abs(eff) / sc["sd_residual"]
        size = int(n_walks or sc["n_walks"])
        # the other transfer, for comparison only: the effect in the paper's method SDs times the study's
        by_sd = (abs(pe["paper_effect"]) / pe["paper_method_sd"] * sc["sd_method"] / sc["sd_residual"]
                 if pe["paper_method_sd"] > 0 else None)
        row.update(effect_study_units=eff, effect_noise_sd=d, effect_noise_sd_by_method_sd=by_sd, n_walks_power=size,
                   power_at_size=finding_power(fid, d, size, n_seeds=n_seeds, seed=[seed, k, size]))
        for w in candidates:
            p = row["power_at_size"] if w == size else finding_power(fid, d, w, n_seeds=n_seeds, seed=[seed, k, w])
            if p >= 0.8:
                row["walks_for_80_percent"] = int(w)
                break
        out[fid] = row
    return out


def agreement_power(folder, *, n_walks: int | None = None, n_seeds: int = 100, seed: int = 0) -> dict:
    """Per metric of a live study: :func:`validation.verdicts.power.power_summary` at ``n_walks`` (default the
    study's) from the scales measured on its walks (:func:`validation.live.evidence.metric_scales`)."""
    raws = _records(Path(folder), "raw.json")
    cfg = config_from_dict(raws[0]["config"])
    _, tables = walk_values(raws, cfg.methods)
    out = {}
    for metric in METRICS:
        sc, n, reason = metric_scales(tables, metric, min_walks=2)
        if sc is None:
            out[metric] = {"status": "not computed", "reason": reason}
            continue
        out[metric] = {"status": "computed", **power_summary(int(n_walks or n), sc, n_seeds=n_seeds, seed=[seed, 1])}
    return out


def markdown(result: dict) -> str:
    """The result of :func:`run` as the Markdown it prints."""
    lines = [f"# What {result['folder']} can decide ({result['kind']}, {result['n_units']} walks)", ""]
    if result.get("agreement"):
        lines += ["## Live vs emulated, per metric (scales measured on the study's walks)", "",
                  "| metric | method SD | walk x method SD | run noise SD | noise / method | walks | smallest "
                  "detectable omega2 | walks for agrees (80 %) | perfect agrees | random disagrees |",
                  "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
        for m, p in result["agreement"].items():
            if p["status"] != "computed":
                lines.append(f"| {m} | {p['reason']} | | | | | | | | |")
                continue
            s = p["scales"]
            lines.append(f"| {m} | {format_number(s['sd_method'])} | {format_number(s['sd_walk_method'])} | {format_number(s['sd_noise'])} | "
                         f"{format_number(p['noise_to_method_sd'], '.2f')} | {p['n_walks']} | "
                         f"{format_number(p['smallest_detectable_omega2'])} | {p['walks_needed_for_agrees'] or '> 240'} | "
                         f"{100 * p['perfect_emulator_rates']['agrees']:.0f} % | "
                         f"{100 * p['random_emulator_rates']['disagrees']:.0f} % |")
        lines.append("")
    lines += ["## Paper-sized findings (per-walk residual measured on the study's walks)", "",
              "| finding | paper effect (its units) | transfer | study level | effect in study units | per-walk "
              "residual SD | effect / residual SD | (by method SD) | power at size | walks for 80 % |",
              "| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for fid, r in result["findings"].items():
        if r["effect_noise_sd"] is None:
            lines.append(f"| {fid} | {format_number(r['paper_effect'])} | {r['transfer']} | | | | | | | {r.get('reason', '')} |")
            continue
        lines.append(f"| {fid} | {format_number(r['paper_effect'])} | {r['transfer']} | {format_number(r['level'])} | "
                     f"{format_number(r['effect_study_units'])} | {format_number(r['sd_residual'])} | {format_number(r['effect_noise_sd'], '.2f')}"
                     f" | {format_number(r['effect_noise_sd_by_method_sd'], '.2f')} | {100 * r['power_at_size']:.0f} % "
                     f"({r['n_walks_power']} walks) | "
                     f"{r['walks_for_80_percent'] or '> 240'} |")
    return "\n".join(lines) + "\n"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``exposim validate study-power``."""
    p.add_argument("folder", type=Path, help="a finished live study or AE study folder")
    p.add_argument("--run", default="emulated-plain",
                   help="live study: the run whose walks the findings' noise is measured on (default emulated-plain, "
                        "what the benchmark judges)")
    p.add_argument("--walks", type=int, help="study size the power is computed at (default: the study's walks)")
    p.add_argument("--seeds", type=int, default=100, help="simulated studies per point (default 100)")
    p.add_argument("--json", type=Path, help="also write the numbers to this JSON file")


def run(args: argparse.Namespace) -> int:
    """Print (and write to ``--json``) what the study folder can decide; a bad folder: one line on stderr, exit 1."""
    try:
        kind, units = study_units(args.folder, args.run)
        result = {"folder": str(args.folder), "kind": kind, "run": args.run if kind == "live" else None,
                  "n_units": len(units),
                  "agreement": agreement_power(args.folder, n_walks=args.walks, n_seeds=args.seeds)
                  if kind == "live" else None,
                  "findings": paper_sized_power(units, n_walks=args.walks, n_seeds=args.seeds)}
    except (ExposimError, OSError) as exc:
        print(f"study_power: {exc}", file=sys.stderr)
        return 1
    print(markdown(result), end="")
    if args.json:
        write_results(args.json, to_jsonable(result))
    return 0


#: ``exposim validate study-power``.
STUDY = Study("study-power", "what a finished live or AE study can decide, from its own walks: the agreement "
              "verdicts' power and the paper-sized findings' power", add_arguments, run)
