"""The report of a run folder: ``results.json`` (summary), ``exposure.png`` and ``report.md``.

Everything comes from ``run.json`` and the per-method CSVs (:mod:`emulator.io.runfolder`),
so :func:`write_run_report` redraws a run's report without recomputing anything.  What a run
emulated from less than a full sweep (partial cycles, large upward ratios) is :mod:`emulator.report.flags`.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

from emulator.cells import DASH, format_number
from emulator.core.native import is_native_run, native_record, run_rate, tick_unit
from emulator.core.settling import TREND_MIN_CHANGE_FRACTION, trending_methods
from emulator.core.stats import compare_methods, statistic_interval
from emulator.io.files import RESULTS_FILE, write_results
from emulator.io.runfolder import read_run_json, read_tables
from emulator.report.figures import legend_outside, log_ticks_at, new_figure, same_as, save
from emulator.report.flags import flags_markdown, run_flags
from emulator.report.html import run_contact_sheet, write_report
from emulator.report.intervals import comparison_table, mark_trending
from emulator.report.words import mode_words, selector_words

__all__ = ["PLOT_FILE", "summarise_run", "run_flags", "exposure_figure", "plot_exposure", "run_markdown",
           "write_run_report", "per_recorder_cycle"]

#: The exposure-against-time figure of a run.
PLOT_FILE = "exposure.png"


def _status(status: str, guarded, cycles) -> str:
    """A method's status: a failure as recorded; a method that fell back in some cycles (a
    non-finite proposal, Kim's failed GP fit: column ``guarded``) is not reported "ok"."""
    n = int(np.sum(guarded)) if len(guarded) else 0
    if status != "ok" or not n:
        return status
    first = [int(c) for c in np.asarray(cycles)[np.asarray(guarded).astype(bool)][:5]]
    more = ", ..." if n > len(first) else ""
    return (f"fell back in {n} of {len(guarded)} cycles (kept its exposure; cycles "
            f"{', '.join(map(str, first))}{more})")


def summarise_run(run_dir: str | os.PathLike, info: dict | None = None, tables: dict | None = None) -> dict:
    """Per-method figures of a run (the content of its ``results.json``)."""
    run_dir = Path(run_dir)
    info = read_run_json(run_dir) if info is None else info
    names = info["methods"]
    tables = read_tables(run_dir, names) if tables is None else tables
    methods = {}
    for name in names:
        t = tables[name]
        target = t["target_ms"]
        n = target.size

        def stat(fn, arr):
            return float(fn(arr)) if arr.size else None

        brackets, counts = np.unique(t["bracket_ms"], return_counts=True) if n else (np.array([]), np.array([]))
        methods[name] = {
            "mode": _mode(info, name),
            "cycles": int(n),
            "mean_exposure_ms": stat(np.mean, target),
            "median_exposure_ms": stat(np.median, target),
            "min_exposure_ms": stat(np.min, target),
            "max_exposure_ms": stat(np.max, target),
            "final_exposure_ms": float(t["next_ms"][-1]) if n else None,
            "mean_saturated_fraction": stat(np.mean, t["saturated_fraction"]),
            "mean_valid_fraction": stat(np.mean, t["valid_fraction"]),
            "non_finite_proposals": int(t["guarded"].sum()),
            "clamped": int(t["clamped"].sum()),
            "bracket_use": {f"{b:g}": int(c) for b, c in zip(brackets, counts)},
            "method_ms_per_frame": (info.get("timing") or {}).get("method_ms_per_frame", {}).get(name),
            "status": _status((info.get("method_status") or {}).get(name, "ok"), t["guarded"], t["cycle"]),
            "fallback_cycles": [int(c) for c in t["cycle"][t["guarded"].astype(bool)]] if n else [],
            **_source_offsets(t),
        }
    unit = tick_unit(info)
    intervals = {
        "definition": f"per method over the run's {unit}, circular block bootstrap (blocks of n^(1/3) consecutive "
                      f"{unit}), 95 %",
        "mean_exposure_ms": {n: {k: v for k, v in statistic_interval(tables[n]["target_ms"], "mean", block=True,
                                                                     seed=[0, k_]).items() if k != "method"}
                             for k_, n in enumerate(names)},
        "mean_saturated_fraction": compare_methods({n: tables[n]["saturated_fraction"] for n in names}, "mean",
                                                   higher_is_better=False, block=True, seed=1),
    }
    summary = {
        "intervals": intervals,
        "run": str(run_dir),
        "sequence": info.get("sequence"),
        "status": info.get("status"),
        "cycles_done": info.get("cycles_done"),
        "n_cycles": info.get("n_cycles"),
        "skipped_cycles": info.get("skipped_cycles", []),
        "selector": info.get("selector"),
        "initial_ms": info.get("initial_ms"),
        "range_ms": info.get("range_ms"),
        "methods": methods,
        "timing": info.get("timing"),
        "rate": run_rate(info),
        **({"shared_memory": info["shared_memory"]} if info.get("shared_memory") else {}),
        **({"gyro_note": native_record(info)["gyro_note"]} if native_record(info).get("gyro_note") else {}),
        **({"latency_frames": info.get("latency_frames"), "n_frames": native_record(info).get("n_frames")}
           if is_native_run(info) else {}),
    }
    flags = run_flags(info, tables)
    if flags is not None:  # only where something is flagged: other runs' results stay as they were
        summary["flags"] = flags
    trending = trending_methods({n: per_recorder_cycle(tables[n])["target_ms"] for n in names})
    if trending:  # only where a method had not settled: other runs' results stay as they were
        summary["still_trending"] = trending
    return summary


def per_recorder_cycle(table: dict) -> dict:
    """A method's table with one row per recorder cycle: at native rate the frames the benchmarks use
    (column ``benchmarked``), at cycle rate the table itself."""
    if "benchmarked" not in table:
        return table
    keep = np.asarray(table["benchmarked"]).astype(bool)
    return {k: np.asarray(v)[keep] for k, v in table.items()}


def _source_offsets(t: dict) -> dict:
    """Native rate: how often each source offset served (frames; 0: the frame's own bracket), and how
    many neighbours were used without a warp (no gyro, a gyro that does not cover them, ``--warp none``, or
    with ``flow-sharp`` a move under its threshold); nothing at cycle rate."""
    if "source_offset" not in t:
        return {}
    offsets, counts = np.unique(t["source_offset"], return_counts=True)
    unwarped = int(np.sum((t["source_offset"] != 0) & np.isnan(t["warp_deg"])))
    return {"source_offsets": {str(int(o)): int(c) for o, c in zip(offsets, counts)}, "unwarped_neighbours": unwarped}


def _mode(info: dict, name: str) -> str:
    """The method's mode as the report shows it: paper/borealhdr, or "plugin" for a method without one."""
    opts = info.get("method_options", {}).get(name, {})
    if opts.get("mode") is not None:
        return str(opts["mode"])
    return "plugin" if opts.get("plugin") else "-"


def exposure_figure(info: dict, tables: dict):
    """The figure of :func:`plot_exposure` (a matplotlib Figure with one axes)."""
    fig, (ax,) = new_figure(1, 9.0, 4.5)
    t0 = min((int(t["timestamp_ns"][0]) for t in tables.values() if t["timestamp_ns"].size), default=0)
    brackets = list(info.get("brackets_ms", []))
    for b in brackets:
        ax.axhline(b, color="0.85", lw=0.8, zorder=0)
    twins = same_as({name: t["target_ms"] for name, t in tables.items() if t["timestamp_ns"].size})
    for name, t in tables.items():
        if not t["timestamp_ns"].size:
            continue
        x = (t["timestamp_ns"] - t0) / 1e9
        if name in twins:
            ax.step(x, t["target_ms"], where="post", ls="--", lw=1.3, label=f"{name} (= {twins[name]})")
        else:
            ax.step(x, t["target_ms"], where="post", marker="o", ms=3, lw=1.3, label=name)
    ax.set_yscale("log")
    log_ticks_at(ax, brackets, data=[float(np.min(t["target_ms"])) for t in tables.values() if t["target_ms"].size])
    ax.set_xlabel("time since first bracket [s]")
    ax.set_ylabel("exposure [ms] (ticks: the brackets, halved below)")
    ax.set_title(f"Exposure per cycle, start {info.get('initial_ms')} ms\n"
                 f"{mode_words(info.get('mode', ''))}", fontsize="medium")
    ax.grid(True, which="major", alpha=0.3)
    legend_outside(ax)
    return fig


def plot_exposure(info: dict, tables: dict, path: str | os.PathLike) -> Path:
    """Target exposure of every method against time (log scale, ticks at the brackets and, where
    a method goes below the shortest one, at its halvings), the brackets as grey lines.

    Methods whose exposure sequences are identical (every value equal) are drawn dashed on top
    of each other and named so in the legend ("= classical-50"); the legend sits outside the data.
    """
    return save(exposure_figure(info, tables), path)


#: A cell of this report: a missing figure prints "-" (the note under the table says what a "-" means).
_fmt = functools.partial(format_number, missing=DASH)


def _rate_lines(info: dict, summary: dict) -> list[str]:
    """The report's words on the rate; at native rate, how often each source offset served."""
    if not is_native_run(summary):
        return []
    nat = native_record(info)
    moved = {"flow": "moved to its instant by the gyro and the optical flow",
             "flow-sharp": f"moved to its instant by the gyro and the optical flow where that moves it "
                           f"{nat.get('sharp_motion_px', 1.0):g} px or more"}.get(nat.get("warp_mode"),
                                                                                 "turned to its instant by the gyro")
    lines = [f"- rate: native (every recorded frame; a proposal made after frame k is used from frame "
             f"k + {1 + int(summary.get('latency_frames') or 0)}); each frame from its own bracket or one within "
             f"{nat.get('window_frames')} frames, "
             f"{moved if nat.get('warp') != 'none' else _unwarped_why(info)}",
             "", "Source frame of each frame, per method (offset in frames; 0: its own bracket):", ""]
    offsets = sorted({int(o) for m in summary["methods"].values() for o in m.get("source_offsets", {})})
    lines += ["| method | " + " | ".join(f"{o:+d}" if o else "0" for o in offsets) + " | unwarped neighbours |",
              "| --- |" + " ---: |" * (len(offsets) + 1)]
    for name, m in summary["methods"].items():
        got = m.get("source_offsets", {})
        lines.append(f"| {name} | " + " | ".join(str(got.get(str(o), 0)) for o in offsets)
                     + f" | {m.get('unwarped_neighbours', 0)} |")
    if nat.get("warp_mode") == "flow-sharp":
        lines += ["", f"Unwarped neighbours include those that moved less than {nat.get('sharp_motion_px', 1.0):g} px "
                      "(used as recorded, on purpose) besides any the gyro does not cover."]
    return lines + [""]


def _unwarped_why(info: dict) -> str:
    """Why a native run's neighbours were not warped: asked (``--warp none``, run.json's ``native_warp``) or no gyro."""
    return "not warped (--warp none)" if info.get("native_warp") == "none" else "not warped (no gyro)"


def _fixed_note(info: dict, summary: dict, tables: dict | None) -> list[str]:
    """What ``fixed`` did: identical to classical-50 only where the two runs' exposures are."""
    if "fixed" not in summary["methods"]:
        return []
    opts = info.get("method_options", {}).get("fixed") or {}
    n = opts.get("n_auto_frames")
    if n is not None and opts.get("mode") == "borealhdr":
        n += 1  # the reference code's counter test adjusts on N + 1 calls
    words = (f"`fixed` runs classical-50 for its first {n if n is not None else 'few'} frames and then "
             "freezes its exposure")
    if is_native_run(summary):
        words += " (with proposals in flight it adjusts only on a frame taken at its previous adjustment)"
    if tables is None or "classical-50" not in tables or "fixed" not in tables:
        return ["", words + "."]
    a, b = np.asarray(tables["fixed"]["target_ms"]), np.asarray(tables["classical-50"]["target_ms"])
    if a.shape == b.shape and np.array_equal(a, b):
        return ["", words + ": on this run it is identical to classical-50 (which had not moved after that)."]
    return ["", words + ": on this run the two differ."]


def _trending_note(summary: dict, unit: str) -> list[str]:
    """The methods whose exposure was still trending at the end (a clip too short for them to settle)."""
    trending = summary.get("still_trending")
    if not trending:
        return []
    k = next(iter(trending.values()))["steps"]
    return ["", f"**Too short to settle:** {len(trending)} of {len(summary['methods'])} method(s) were still "
            f"moving one way over the last {k} recorder cycles (by {100 * TREND_MIN_CHANGE_FRACTION:g} % or more): "
            + ", ".join(f"{n} ({t['direction']} {100 * abs(t['change_fraction']):.0f} %)" for n, t in trending.items())
            + ". Their figures describe the approach to an operating point, not the point; a longer recording is "
            "needed before calling them better or worse."]


def run_markdown(info: dict, summary: dict, tables: dict | None = None) -> str:
    """The markdown report of a run (``tables``: the per-method tables, for the note on ``fixed``)."""
    native = is_native_run(summary)
    unit = tick_unit(summary)
    flags = summary.get("flags")
    flagged = _flagged_words(flags)
    lines = [
        f"# AE closed-loop run: {Path(info.get('sequence', '')).name}",
        "",
        f"- sequence: `{info.get('sequence')}`",
        f"- status: {info.get('status')}, cycles {info.get('cycles_done')}/{info.get('n_cycles')}{flagged}"
        if not native else
        f"- status: {info.get('status')}, frames {info.get('cycles_done')}/{summary.get('n_frames')} of "
        f"{info.get('n_cycles')} recorder cycles{flagged}",
        *_rate_lines(info, summary),
        f"- methods: {mode_words(info.get('mode'))} (`--mode {info.get('mode')}`)",
        f"- brackets chosen by {selector_words(info.get('selector'))} (`--selector {info.get('selector')}`; the left "
        "camera's saturation decides for both)" if not native else
        "- source frames chosen by the native selector (upward ratio against time offset and clipping; the left "
        "camera decides for both)",
        f"- initial exposure {info.get('initial_ms')} ms, clamp {info.get('range_ms')} ms, response `{info.get('response')}`",
        f"- images: {info.get('save')}",
        f"- command: `{info.get('command') or '(library call)'}`, "
        f"exposim {info.get('version')}",
        "",
        f"![exposure against time]({PLOT_FILE})",
        "",
        "The paper (section V-D) compares the methods through features and VO, and shows no",
        "exposure-against-time figure; this plot is the run's own record.",
        "",
        *_methods_table(summary, unit),
    ]
    lines += _intervals_lines(summary)
    lines += ["", "Saturated: pixels at the black or the white level in the emulated image; valid: pixels the emulation "
              "could reconstruct (not clipped in the source bracket: a black source pixel emulated upwards is not valid). \"-\": no cycle of that method (or no timing recorded)."]
    lines += _fixed_note(info, summary, tables)
    lines += _trending_note(summary, unit)
    lines += _status_lines(summary, unit)
    if flags is not None:
        lines += flags_markdown(flags, unit)
    lines += _timing_lines(summary.get("timing") or {}, unit)
    return "\n".join(lines) + "\n"


def _flagged_words(flags: dict | None) -> str:
    """The status line's pointer to the Flags section ("" when nothing is flagged)."""
    if flags is None:
        return ""
    above = sum(1 for m in flags["methods"].values() if m["cycles_above_ratio_bound"])
    return (f" ({len(flags['partial_cycles'])} partial"
            + (f", {flags['partial_cycles_skipped']} left out" if flags["partial_cycles_skipped"] else "")
            + (f"; {above} method(s) emulated up by more than {flags['upward_ratio_bound']:g}x" if above else "")
            + ": see Flags)")


def _methods_table(summary: dict, unit: str) -> list[str]:
    """The report's table of each method's exposure, saturation, validity and speed."""
    lines = [f"| method | mode | {unit} | mean ms | median ms | min ms | max ms | mean saturated (%) | mean valid (%) | "
             "non-finite | ms/frame |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    pct = lambda v: None if v is None else 100.0 * v  # noqa: E731
    for name, m in summary["methods"].items():
        lines.append(
            f"| {name} | {m['mode']} | {m['cycles']} | {_fmt(m['mean_exposure_ms'])} | {_fmt(m['median_exposure_ms'])} | "
            f"{_fmt(m['min_exposure_ms'])} | {_fmt(m['max_exposure_ms'])} | {_fmt(pct(m['mean_saturated_fraction']), '.2f')} | "
            f"{_fmt(pct(m['mean_valid_fraction']), '.2f')} | {m['non_finite_proposals']} | {_fmt(m['method_ms_per_frame'], '.1f')} |"
        )
    return lines


def _intervals_lines(summary: dict) -> list[str]:
    """The mean exposures with their intervals and the saturation comparison (none for a summary without them)."""
    iv = summary.get("intervals")
    if not iv:
        return []
    lines = ["", "Mean exposure per method with its 95 % interval (" + iv["definition"] + "): "
             + ", ".join(f"{n} {_fmt(r['estimate'])} ms [{_fmt(r['ci95'][0] if r['ci95'] else None)}, "
                         f"{_fmt(r['ci95'][1] if r['ci95'] else None)}]" for n, r in iv["mean_exposure_ms"].items())
             + ".", "", "Mean saturated fraction (%), lower is better:", ""]
    return lines + comparison_table(mark_trending(iv["mean_saturated_fraction"], summary.get("still_trending") or {}),
                                    "mean saturated (%)", spec=".2f", scale=100.0)


def _status_lines(summary: dict, unit: str) -> list[str]:
    """The methods that fell back or failed, and the skipped cycles (or frames)."""
    failed = {n: m["status"] for n, m in summary["methods"].items() if m.get("status", "ok").startswith("failed")}
    fell = {n: m["status"] for n, m in summary["methods"].items() if m.get("status", "ok").startswith("fell back")}
    lines = []
    if fell:
        lines += ["", f"Methods that fell back (kept their exposure; column `guarded`): {len(fell)}"]
        lines += [f"- {n}: {why}" for n, why in fell.items()]
    if failed:
        lines += ["", f"Failed methods: {len(failed)} (their rows stop before the cycle named)"]
        lines += [f"- {n}: {why}" for n, why in failed.items()]
    skipped = summary.get("skipped_cycles") or []
    lines += ["", f"Skipped {unit}: {len(skipped)}"]
    for s in skipped:
        lines.append(f"- {unit[:-1]} {s['cycle']}: {s['reason']}")
    return lines


def _timing_lines(timing: dict, unit: str) -> list[str]:
    """The run's speed: ticks per second, decodes and emulations (none when no timing was recorded)."""
    if not timing:
        return []
    return [
        "",
        f"Timing: {timing.get('cycles')} {unit} in {_fmt(timing.get('wall_s'))} s "
        f"({_fmt(timing.get('cycles_per_s'))} {unit}/s), {timing.get('decodes')} PNG decodes "
        f"({_fmt(timing.get('decode_ms_per_image'), '.1f')} ms each), {timing.get('emulations')} emulations "
        f"({_fmt(timing.get('emulate_ms_per_image'), '.1f')} ms each).",
    ]


def write_run_report(run_dir: str | os.PathLike, info: dict | None = None, tables: dict | None = None) -> dict:
    """(Re)write ``results.json``, ``exposure.png`` and ``report.md`` of a run folder.

    Returns the results dictionary.  Needs no recomputation: everything comes from
    ``run.json`` and the per-method CSVs, or from ``info`` and ``tables`` when the run
    passes them from memory (:func:`emulator.io.runfolder.tables_from_rows`).
    """
    run_dir = Path(run_dir)
    info = read_run_json(run_dir) if info is None else info
    tables = read_tables(run_dir, info["methods"]) if tables is None else tables
    summary = summarise_run(run_dir, info, tables)
    plot_exposure(info, tables, run_dir / PLOT_FILE)
    write_results(run_dir / RESULTS_FILE, summary)
    sheet = run_contact_sheet(run_dir, info["methods"], tables, white_level=info.get("white_level"))
    write_report(run_dir, run_markdown(info, summary, tables), figures=[PLOT_FILE], sheets=[sheet])
    return summary
