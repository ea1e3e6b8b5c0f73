"""``exposim bench compare``: the methods of several run folders side by side, in one ranking.

Each input is either a run folder of ``exposim run`` (any rate) or an output folder of ``exposim
bench features``; all inputs are of one kind and of one recording.  Every (method, input) becomes a
row, named by the method alone where that is unique, else by the method and the rate
(``classical-50 (native)``), else by the method and the folder.  So a plugin-only run and an earlier
run of the built-ins make one ranking, and a cycle-rate and a native-rate run of the same methods
stand side by side.

The unit of comparison is the recorder cycle: a native-rate run contributes the frames the
benchmarks use (one per recorder cycle, column ``benchmarked``), so that both rates are judged on
the same instants; rows are paired on the recorder cycles they all have.  Run folders are compared on
the mean saturated fraction (lower is better) with the mean exposure beside it; feature folders on
the median matches between consecutive images (higher is better) and the median uniformity.
Intervals: circular block bootstrap over the units (:func:`emulator.core.stats.compare_methods`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from emulator.errors import MetricsError
from emulator.io.files import RESULTS_FILE, prepare_output, read_metadata, write_results
from emulator.io.runcsv import read_tables
from emulator.io.runfolder import RUN_FILE, read_run_json
from emulator.core.native import is_native_run, run_rate
from emulator.core.settling import trending_methods
from emulator.core.stats import compare_methods, statistic_interval
from emulator.report.compare import compare_markdown
from emulator.report.html import write_report
from emulator.report.run import per_recorder_cycle
from emulator.version import __version__

__all__ = ["bench_compare", "load_inputs", "row_labels"]


def _recording(info: dict) -> str | None:
    seq = info.get("sequence")
    return None if not seq else Path(str(seq)).name


def _run_input(folder: Path) -> dict:
    info = read_run_json(folder)
    names = list(info["methods"])
    tables = read_tables(folder, names)
    methods = {}
    for name in names:
        t = per_recorder_cycle(tables[name])
        units = t["recorder_cycle"] if "recorder_cycle" in t else t["cycle"]
        methods[name] = {"units": [int(u) for u in units],
                         "saturated_fraction": np.asarray(t["saturated_fraction"], dtype=np.float64),
                         "exposure_ms": np.asarray(t["target_ms"], dtype=np.float64)}
    return {"folder": str(folder), "kind": "run", "rate": run_rate(info), "mode": info.get("mode"),
            "latency_frames": info.get("latency_frames") if is_native_run(info) else None,
            "recording": _recording(info), "methods": methods}


def _features_input(folder: Path, results: dict) -> dict:
    methods, rates, recordings = {}, set(), set()
    for run in results.get("runs", []):
        run_dir = Path(run["run_dir"])
        info = read_run_json(run_dir) if (run_dir / RUN_FILE).is_file() else {}
        rates.add(info.get("rate") or ("cycle" if info else "unknown"))
        recordings.add(_recording(run) or _recording(info))
        for name, m in run["methods"].items():
            entry = methods.setdefault(name, {"matches": [], "uniformity": []})
            entry["matches"] += [float(v) for v in m.get("matches", [])]
            entry["uniformity"] += [float(v) for v in m.get("uniformity", [])]
    if len(rates) > 1 or len(recordings) > 1:
        raise MetricsError(f"{folder}: its runs are of several recordings or rates; compare features folders of one "
                           "recording and one rate each")
    for entry in methods.values():
        entry["units"] = list(range(len(entry["uniformity"])))
    return {"folder": str(folder), "kind": "features", "rate": rates.pop() if rates else "unknown",
            "recording": recordings.pop() if recordings else None, "methods": methods}


def load_inputs(folders) -> list[dict]:
    """Each folder read as a run folder or a ``bench features`` folder (one kind for all, one recording)."""
    inputs = []
    for folder in map(Path, folders):
        results = read_metadata(folder / RESULTS_FILE, MetricsError)  # {} where there is none
        if isinstance(results, dict) and results.get("benchmark") == "features":
            inputs.append(_features_input(folder, results))
        elif (folder / RUN_FILE).is_file():
            inputs.append(_run_input(folder))
        else:
            raise MetricsError(f"{folder}: neither a run folder (run.json) nor a `bench features` folder "
                               "(results.json of benchmark features)")
    kinds = {i["kind"] for i in inputs}
    if len(kinds) > 1:
        raise MetricsError("give run folders or `bench features` folders, not both: "
                           + ", ".join(f"{i['folder']} ({i['kind']})" for i in inputs))
    recordings = {i["recording"] for i in inputs if i["recording"] is not None}
    if len(recordings) > 1:
        raise MetricsError(f"the folders are of different recordings ({', '.join(sorted(recordings))}); a comparison "
                           "ranks methods on one recording")
    return inputs


def row_labels(inputs: list[dict]) -> list[tuple[str, int, str]]:
    """``(label, input index, method)`` of every row: the method's name where it is unique, else the
    method and the rate, else the method and the folder's name."""
    pairs = [(k, name) for k, inp in enumerate(inputs) for name in inp["methods"]]
    by_name: dict[str, list[int]] = {}
    for k, name in pairs:
        by_name.setdefault(name, []).append(k)
    out = []
    for k, name in pairs:
        ks = by_name[name]
        if len(ks) == 1:
            label = name
        elif len({inputs[j]["rate"] for j in ks}) == len(ks):
            label = f"{name} ({inputs[k]['rate']})"
        else:
            label = f"{name} ({Path(inputs[k]['folder']).name})"
        out.append((label, k, name))
    if len({label for label, _, _ in out}) < len(out):
        raise MetricsError("two inputs give the same method under the same folder name and rate; rename a folder")
    return out


def _paired(rows: dict, key: str) -> tuple[dict, int]:
    """Each row's values on the units every row has (paired), or on its own units where fewer than 2 are
    common; the number of common units."""
    common = set.intersection(*(set(r["units"]) for r in rows.values())) if rows else set()
    out = {}
    for label, r in rows.items():
        values = np.asarray(r[key], dtype=np.float64)
        if len(common) >= 2 and len(values) == len(r["units"]):
            keep = [i for i, u in enumerate(r["units"]) if u in common]
            values = values[keep]
        out[label] = values
    return out, len(common)


def _comparisons(kind: str, rows: dict) -> dict:
    if kind == "run":
        sat, n_common = _paired(rows, "saturated_fraction")
        exp, _ = _paired(rows, "exposure_ms")
        return {
            "primary": "mean_saturated_fraction",
            "n_common_units": n_common,
            "mean_saturated_fraction": compare_methods(sat, "mean", higher_is_better=False, block=True, seed=1),
            "mean_exposure_ms": {m: {k: v for k, v in statistic_interval(x, "mean", block=True, seed=[0, i]).items()
                                     if k != "method"} for i, (m, x) in enumerate(exp.items())},
            "still_trending": trending_methods({m: r["exposure_ms"] for m, r in rows.items()}),
        }
    matches = {m: r["matches"] for m, r in rows.items()}
    uniformity, n_common = _paired(rows, "uniformity")
    return {
        "primary": "median_matches",
        "n_common_units": n_common,
        "median_matches": compare_methods(matches, "median", block=True, seed=0),
        "median_uniformity": compare_methods(uniformity, "median", block=True, seed=1),
        "still_trending": {},
    }


def bench_compare(folders, out_dir: str | os.PathLike, *, force: bool = False, command: str | None = None) -> dict:
    """Compare the methods of ``folders`` (run folders, or ``bench features`` folders) in one table.

    Parameters
    ----------
    folders : sequence of path-like
        Two or more folders of one kind and one recording (one folder is allowed: its methods ranked).
    out_dir : path-like
        Output folder: ``results.json``, ``report.md``, ``report.html``.
    force : bool
        Overwrite an existing ``results.json``.
    command : str, optional
        The command line, recorded.

    Returns
    -------
    dict
        The content of ``results.json``: the inputs, every row (method, rate, folder), the comparisons
        with 95 % intervals and the ranking (best first).
    """
    folders = [Path(f) for f in folders]
    if not folders:
        raise MetricsError("give at least one folder to compare")
    inputs = load_inputs(folders)
    labels = row_labels(inputs)
    rows = {label: inputs[k]["methods"][name] for label, k, name in labels}
    cmp = _comparisons(inputs[0]["kind"], rows)
    primary = cmp[cmp["primary"]]
    have = [m for m, r in primary["methods"].items() if r["estimate"] is not None]
    ranking = sorted(have, key=lambda m: primary["methods"][m]["estimate"],
                     reverse=cmp["primary"] == "median_matches")
    results = {
        "benchmark": "compare",
        "exposim_version": __version__,
        "command": command,
        "kind": inputs[0]["kind"],
        "unit": "recorder cycle" if inputs[0]["kind"] == "run" else "consecutive image pair (matches), image "
                "(uniformity)",
        "inputs": [{k: v for k, v in inp.items() if k != "methods"} | {"methods": list(inp["methods"])}
                   for inp in inputs],
        "rows": {label: {"method": name, "rate": inputs[k]["rate"], "folder": inputs[k]["folder"],
                         "n_units": len(rows[label]["units"])} for label, k, name in labels},
        "comparisons": cmp,
        "ranking": ranking,
        "report": "report.md",
    }
    out = prepare_output(out_dir, force=force)

    write_report(out, compare_markdown(results), figures=[])
    write_results(out / RESULTS_FILE, results)
    return results
