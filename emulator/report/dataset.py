"""The summary of a whole-dataset run: ``results.json``, ``report.md`` and ``methods.png``.

Per-sequence tables (each method's figures on each sequence, from the units' own
``results.json``), per-method tables over the sequences, and the throughput with its
projection to the full BorealHDR dataset (:func:`emulator.orchestration.datasetrun.throughput`).
"""

from __future__ import annotations

import os
from functools import partial
from pathlib import Path

import numpy as np

from emulator.cells import DASH, format_number
from emulator.io.files import REPORT_FILE, RESULTS_FILE, write_results, write_text
from emulator.report.figures import new_figure, save
from emulator.report.html import write_report, run_folder_pages
from emulator.core.stats import compare_methods
from emulator.report.intervals import comparison_table

__all__ = ["PLOT_FILE", "per_method_table", "method_intervals", "plot_methods", "dataset_markdown", "write_dataset_report"]

#: The per-method, per-sequence exposure figure of a dataset run.
PLOT_FILE = "methods.png"


def per_method_table(per_sequence: dict, methods: list[str]) -> dict:
    """Per method over sequences: cycles (sum), cycle-weighted means of exposure, saturation, validity."""
    table = {}
    for m in methods:
        rows = [s[m] for s in per_sequence.values() if m in s and s[m].get("cycles")]
        n = np.array([r["cycles"] for r in rows], dtype=float)

        def wmean(key):
            vals = [(r[key], k) for r, k in zip(rows, n) if r.get(key) is not None]
            return float(sum(v * k for v, k in vals) / sum(k for _, k in vals)) if vals else None

        table[m] = {
            "sequences": len(rows),
            "cycles": int(n.sum()),
            "mean_exposure_ms": wmean("mean_exposure_ms"),
            "mean_saturated_fraction": wmean("mean_saturated_fraction"),
            "mean_valid_fraction": wmean("mean_valid_fraction"),
            "non_finite_proposals": int(sum(r.get("non_finite_proposals", 0) for r in rows)),
            "clamped": int(sum(r.get("clamped", 0) for r in rows)),
            "method_ms_per_frame": wmean("method_ms_per_frame"),
        }
    return table


def method_intervals(per_sequence: dict, methods: list[str]) -> dict:
    """Per method over the sequences (the independent units): mean exposure and mean saturated fraction with
    95 % bootstrap intervals, and each method's difference from the best (least saturated), paired by sequence
    (:func:`emulator.core.stats.compare_methods`).  A sequence missing a method leaves the pairs unaligned."""
    seqs = list(per_sequence)

    def col(key):
        return {m: [((per_sequence[s].get(m) or {}).get(key)) for s in seqs] for m in methods}

    def arr(d):
        return {m: [float("nan") if v is None else float(v) for v in vals] for m, vals in d.items()}

    return {"definition": "bootstrap over sequences (units), 95 %",
            "mean_exposure_ms": compare_methods(arr(col("mean_exposure_ms")), "mean", seed=0),
            "mean_saturated_fraction": compare_methods(arr(col("mean_saturated_fraction")), "mean",
                                                       higher_is_better=False, seed=1)}


def plot_methods(summary: dict, path: str | os.PathLike) -> Path:
    """Mean target exposure of every method on every sequence (log scale)."""
    seqs = list(summary["per_sequence"])
    fig, (ax,) = new_figure(1, max(6.0, 1.2 * len(seqs) + 3), 4.5)
    x = np.arange(len(seqs))
    methods = summary["methods"]
    width = 0.8 / max(len(methods), 1)
    for i, m in enumerate(methods):
        y = [summary["per_sequence"][s].get(m, {}).get("mean_exposure_ms") for s in seqs]
        y = [np.nan if v is None else v for v in y]
        ax.bar(x - 0.4 + (i + 0.5) * width, y, width, label=m)
    ax.set_xticks(x, seqs, rotation=20, ha="right", fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("mean target exposure [ms]")
    ax.set_title("Mean exposure per method and sequence")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=8, ncol=2)
    return save(fig, path)


#: A figure of the dataset report: the house rule, a missing value as ``-`` (the report's tables always printed it so).
_fmt = partial(format_number, missing=DASH)


def dataset_markdown(summary: dict) -> str:
    """The markdown report of a dataset run."""
    t = summary["throughput"]
    lines = [
        "# AE closed-loop runs over a dataset",
        "",
        f"- root: `{summary['root']}`",
        f"- sequences: {len(summary['sequences'])}, methods: {', '.join(summary['methods'])}",
        f"- units (sequence, method group): {len(summary['units'])} done, {len(summary['errors'])} failed; "
        f"scheduler {summary['scheduler']}",
        "",
        f"![mean exposure per method and sequence]({PLOT_FILE})",
        "",
        "## Per method over sequences (cycle-weighted means)",
        "",
        "| method | sequences | cycles | mean ms | mean sat. | mean valid | non-finite | clamped | ms/frame |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for m, r in summary["per_method"].items():
        lines.append(f"| {m} | {r['sequences']} | {r['cycles']} | {_fmt(r['mean_exposure_ms'])} | "
                     f"{_fmt(r['mean_saturated_fraction'], '.2%')} | {_fmt(r['mean_valid_fraction'], '.2%')} | "
                     f"{r['non_finite_proposals']} | {r['clamped']} | {_fmt(r['method_ms_per_frame'], '.1f')} |")
    iv = summary.get("method_intervals")
    if iv and len(summary["per_sequence"]) >= 2:
        lines += ["", f"## Methods compared over sequences ({iv['definition']})", "",
                  "Mean saturated fraction (%) per sequence, lower is better:", ""]
        lines += comparison_table(iv["mean_saturated_fraction"], "mean saturated (%)", spec=".2f", scale=100.0)
    lines += ["", "## Per sequence: mean target exposure (ms)", "",
              "| sequence | " + " | ".join(summary["methods"]) + " |",
              "| --- |" + " ---: |" * len(summary["methods"])]
    for s, per in summary["per_sequence"].items():
        lines.append(f"| {s} | " + " | ".join(_fmt(per.get(m, {}).get("mean_exposure_ms")) for m in summary["methods"])
                     + " |")
    lines += [
        "",
        "## Throughput",
        "",
        f"- {t['cycles']} cycles, {t['images']} images (one per shot, a stereo pair once) in {_fmt(t['worker_s'])} "
        f"worker-seconds of closed loop (all methods): {_fmt(t['seconds_per_cycle'])} s per cycle, "
        f"{_fmt(t['cycles_per_s_one_worker'])} cycles/s and {_fmt(t['images_per_s_one_worker'])} images/s on one worker",
        f"- this invocation: {t['units_computed']} units computed in {_fmt(t['wall_s'])} s wall "
        f"({_fmt(t['cycles_per_s_wall'])} cycles/s, {_fmt(t['images_per_s_wall'])} images/s, all methods)",
        "",
    ]
    if t["projection"]:
        lines += ["Projection to the full BorealHDR dataset (55 trajectories, 393 238 images, 5 h; "
                  f"{_fmt(t['images_per_cycle'])} images per cycle) from the measured cost per cycle "
                  "(units taken as equal):", "",
                  "| workers | busy | wall hours | cycles/s | images/s | x real time |",
                  "| ---: | ---: | ---: | ---: | ---: | ---: |"]
        for p in t["projection"]:
            lines.append(f"| {p['n_workers']} | {p['busy_workers']} | {_fmt(p['wall_hours'])} | {_fmt(p['cycles_per_s'])} | "
                         f"{_fmt(p['images_per_s'])} | {_fmt(p['real_time_factor'])} |")
    if summary["errors"]:
        lines += ["", "## Failed units", ""] + [f"- {e['unit']}: {e['error']}" for e in summary["errors"]]
    failed = summary.get("failed_methods") or {}
    if failed:
        lines += ["", f"## Methods that failed in every unit: {len(failed)}", ""]
        lines += [f"- {m}: {why}" for m, why in failed.items()]
    return "\n".join(lines) + "\n"


def write_dataset_report(out_dir: str | os.PathLike, summary: dict) -> dict:
    """Add the per-method table to ``summary`` and write ``results.json``, ``report.md``, ``methods.png``."""
    out = Path(out_dir)
    summary = {**summary, "per_method": per_method_table(summary["per_sequence"], summary["methods"]),
               "method_intervals": method_intervals(summary["per_sequence"], summary["methods"])}
    write_results(out / RESULTS_FILE, summary)
    if summary["per_sequence"] and summary["units"]:
        plot_methods(summary, out / PLOT_FILE)
    write_report(out, dataset_markdown(summary), figures=[PLOT_FILE], sheets=[_unit_pages(out, summary)])
    return summary


def _unit_pages(out: Path, summary: dict) -> str:
    """HTML: a link to every unit's own report.html, and the first unit's contact sheet."""
    return run_folder_pages(out, [(f"{u['sequence']} / {u['group']}", u["folder"]) for u in summary["units"]])
