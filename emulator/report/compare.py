"""The report of ``exposim bench compare``: one ranking of the methods of several folders, and each method's
results by rate side by side (:func:`emulator.metrics.compare.bench_compare`)."""

from __future__ import annotations

from pathlib import Path

from emulator.cells import DASH, format_number
from emulator.report.intervals import comparison_table, mark_trending

__all__ = ["compare_markdown", "by_rate_table"]

_LABELS = {
    "mean_saturated_fraction": ("mean saturated (%)", ".2f", 100.0),
    "median_matches": ("median matches", ".1f", 1.0),
    "median_uniformity": ("median uniformity (%)", ".1f", 100.0),
}


def _cell(r: dict | None, spec: str, scale: float) -> str:
    if not r or r.get("estimate") is None:
        return DASH
    iv = r.get("ci95")
    text = format_number(scale * r["estimate"], spec)
    return text + (f" [{format_number(scale * iv[0], spec)}, {format_number(scale * iv[1], spec)}]" if iv else "")


def by_rate_table(results: dict, key: str, label: str, spec: str, scale: float) -> list[str]:
    """A markdown table: one row per method, one column per rate (or folder), each cell the statistic
    ``key`` with its 95 % interval."""
    rows = results["rows"]
    stats = results["comparisons"][key]
    stats = stats["methods"] if "methods" in stats else stats
    columns = list(dict.fromkeys(r["rate"] if _by_rate(results) else r["folder"] for r in rows.values()))
    methods = list(dict.fromkeys(r["method"] for r in rows.values()))
    cells = {(r["method"], r["rate"] if _by_rate(results) else r["folder"]): stats.get(lab)
             for lab, r in rows.items()}
    names = columns if _by_rate(results) else [Path(c).name for c in columns]
    lines = ["| method | " + " | ".join(f"{label}, {c}" for c in names) + " |",
             "| --- |" + " ---: |" * len(columns)]
    for m in methods:
        lines.append(f"| {m} | " + " | ".join(_cell(cells.get((m, c)), spec, scale) for c in columns) + " |")
    return lines


def _by_rate(results: dict) -> bool:
    """Columns by rate where each (method, rate) occurs once, else by folder."""
    seen = [(r["method"], r["rate"]) for r in results["rows"].values()]
    return len(seen) == len(set(seen))


def compare_markdown(results: dict) -> str:
    """The markdown report of :func:`emulator.metrics.compare.bench_compare`."""
    cmp = results["comparisons"]
    primary = cmp["primary"]
    label, spec, scale = _LABELS[primary]
    lines = ["# Methods side by side", "", "Folders compared (one recording):", ""]
    for inp in results["inputs"]:
        lat = f", latency {inp['latency_frames']} frame(s)" if inp.get("latency_frames") is not None else ""
        lines.append(f"- `{inp['folder']}` ({inp['kind']}, rate {inp['rate']}{lat}): {', '.join(inp['methods'])}")
    lines += ["", f"Unit of comparison: the {results['unit']}; a native-rate run contributes the frames the "
              "benchmarks use (one per recorder cycle), so both rates are judged on the same instants."
              + (f" Rows are paired on the {cmp['n_common_units']} units they all have." if cmp["n_common_units"] >= 2
                 else " The rows share fewer than 2 units and are resampled independently."), "",
              "## One ranking", "",
              f"{label}, {'lower' if primary == 'mean_saturated_fraction' else 'higher'} is better; 95 % intervals "
              "by a circular block bootstrap over the units; \"cannot tell apart\": the difference's interval "
              "holds 0:", ""]
    lines += comparison_table(mark_trending(cmp[primary], cmp.get("still_trending") or {}), label, spec=spec,
                              scale=scale)
    lines += ["", "Ranking: " + " > ".join(results["ranking"]) + "." if results["ranking"] else "", ""]
    columns = "rate" if _by_rate(results) else "folder"
    lines += [f"## By method and {columns}", ""]
    lines += by_rate_table(results, primary, label, spec, scale)
    if primary == "mean_saturated_fraction":
        lines += [""] + by_rate_table(results, "mean_exposure_ms", "mean exposure (ms)", ".3g", 1.0)
    else:
        lines += [""] + by_rate_table(results, "median_uniformity", *_LABELS["median_uniformity"])
    trending = cmp.get("still_trending") or {}
    if trending:
        lines += ["", f"**Too short to settle:** still moving one way at the end: "
                  + ", ".join(f"{m} ({t['direction']} {100 * abs(t['change_fraction']):.0f} % over the last "
                              f"{t['steps']} recorder cycles)" for m, t in trending.items())
                  + ". Their place in the ranking describes the approach, not the operating point."]
    lines += ["", f"Command: `{results.get('command') or '(library call)'}`", ""]
    return "\n".join(lines)
