"""Writing the validation experiments: results.json, arrays.npz, PNG figures and report.md.

Plots with matplotlib's ``Figure`` API on an Agg canvas (no ``pyplot``, so a notebook's
backend is left alone) and assembles an output folder (through :mod:`emulator.io.files`);
the experiment modules return dicts and arrays.  The emulation study's figures and
``report.md`` live in its package (:mod:`validation.emulation.report`), those of the
selector, motion and speed studies here.  :func:`run_experiment` is what
``exposim validate`` calls.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from emulator.io.files import (
    REPORT_FILE,
    RESULTS_FILE,
    prepare_output,
    save_figure,
    write_arrays,
    write_results,
    write_text,
)
from emulator.report.figures import subplots
from emulator.report.html import write_report
from validation.common import ValidationError, provenance
from validation.emulation import EmulationConfig, run_emulation
from validation.emulation.report import emulation_figures, emulation_markdown, emulation_verdict
from validation.motion import MotionConfig, run_motion
from validation.selectors import SelectorsConfig, run_selectors
from validation.speed import SpeedConfig, run_speed
from emulator.cells import format_number

__all__ = ["EXPERIMENTS", "make_config", "run_experiment", "emulation_verdict"]

EXPERIMENTS = ("emulation", "selectors", "motion", "speed")
#: Each experiment's configuration class.
_CONFIGS = {"emulation": EmulationConfig, "selectors": SelectorsConfig, "motion": MotionConfig, "speed": SpeedConfig}


def make_config(name: str, *, quick: bool = False, **overrides):
    """The configuration object of experiment ``name`` (quick or full), with overrides."""
    overrides = {k: v for k, v in overrides.items() if v is not None}
    C = _CONFIGS.get(name)
    if C is None:
        raise ValidationError(f"unknown experiment {name!r}; choose from {', '.join(EXPERIMENTS)}")
    import dataclasses

    fields = {f.name for f in dataclasses.fields(C)}
    unknown = sorted(set(overrides) - fields)
    if unknown:
        raise ValidationError(f"{name}: option(s) {', '.join(unknown)} do not apply to this experiment")
    return C.quick(**overrides) if quick else C(**overrides)


def run_experiment(name: str, output, *, config=None, quick: bool = False, force: bool = False, command: str = "",
                   progress=None, **overrides) -> dict:
    """Run experiment ``name`` and write its folder; returns the results dict.

    Parameters
    ----------
    name : str
        One of :data:`EXPERIMENTS`.
    output : path
        Output folder; refused when it holds a results.json unless ``force``.
    config : dataclass, optional
        Ready configuration (else built by :func:`make_config` from ``quick`` and overrides).
    command : str
        The command line recorded in results.json.
    progress : callable, optional
        Called with a step count as the experiment advances (see ``config.n_steps()``).
    """
    if config is None:
        config = make_config(name, quick=quick, **overrides)
    folder = prepare_output(output, force=force)
    if name == "emulation":
        out = run_emulation(config, progress=progress)
        figures = emulation_figures(out, folder)
        md = emulation_markdown(out["results"], figures)
    elif name == "selectors":
        out = run_selectors(config, progress=progress)
        figures = _selectors_figures(out, folder)
        md = _selectors_md(out["results"], figures)
    elif name == "motion":
        out = run_motion(config, progress=progress)
        figures = _motion_figures(out, folder)
        md = _motion_md(out["results"], figures)
    else:
        out = run_speed(config, progress=progress)
        figures = _speed_figures(out, folder)
        md = _speed_md(out["results"], figures)
    results = dict(out["results"])
    results["provenance"] = provenance(name, config.as_dict())
    results["provenance"]["command"] = command
    results["figures"] = figures
    write_arrays(folder / "arrays.npz", out["arrays"])
    write_results(folder / RESULTS_FILE, results, float_digits=12)
    write_report(folder, md)
    return results


# ------------------------------------------------------------------------------------------ selectors
def _selectors_figures(out: dict, folder: Path) -> list[str]:
    r, a = out["results"], out["arrays"]
    exposures = a["exposures_ms"]
    names = []
    fig, axes = subplots(1, 2, figsize=(12, 4), sharey=True)
    for ax, split in zip(axes, ("train", "test")):
        scenes_ = r["train_scenes"] if split == "train" else r["test_scenes"]
        for n_i, name in enumerate(r["selectors"]):
            curves = []
            for s in scenes_:
                for resp in r["responses"]:
                    err = a[f"{s}/{resp}/err"]
                    idx = a[f"{s}/{resp}/choice/{name}"]
                    orc = a[f"{s}/{resp}/choice/oracle"]
                    rows = np.arange(err.shape[0])
                    curves.append(err[rows, idx] - err[rows, orc])
            ax.plot(exposures, np.mean(curves, axis=0), lw=1.5 if name != "oracle" else 0.8, label=name,
                    color=f"C{n_i}")
        ax.set_xscale("log")
        ax.set_yscale("symlog", linthresh=0.05)
        ax.set_ylim(bottom=0.0)
        ax.set_xlabel("target exposure (ms)")
        ax.set_title(f"{split} scenes: mean excess RMSE over the oracle")
        ax.grid(alpha=0.3, which="both")
    axes[0].set_ylabel("RMSE - oracle RMSE (% of DN range)")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, folder / "excess_vs_exposure.png", dpi=110)
    names.append("excess_vs_exposure.png")

    fig, ax = subplots(figsize=(8, 3.8))
    x = np.arange(len(r["selectors"]))
    for k, split in enumerate(("train", "test")):
        vals = [r["summary"][split]["exact_all"][n]["excess_over_oracle"]["mean"] for n in r["selectors"]]
        ax.bar(x + (k - 0.5) * 0.4, vals, 0.4, label=f"{split} scenes")
    ax.set_xticks(x, r["selectors"])
    ax.set_ylabel("mean excess over oracle (% of DN range)")
    ax.legend()
    fig.tight_layout()
    save_figure(fig, folder / "selector_summary.png", dpi=110)
    names.append("selector_summary.png")
    return names


def _selectors_md(r: dict, figures: list[str]) -> str:
    pe = r["predicted_error"]
    L = ["# Bracket selectors against an oracle", "", r["metric"] + ".", "",
         f"Training scenes: {', '.join(r['train_scenes'])}; held-out scenes: {', '.join(r['test_scenes'])}; "
         f"responses: {', '.join(r['responses'])}.", ""]
    for split in ("test", "train"):
        L += [f"## {'Held-out' if split == 'test' else 'Training'} scenes", "",
              "| selector | median RMSE | mean RMSE | max RMSE | mean excess over oracle | max excess | "
              "agrees with oracle |", "| --- | --- | --- | --- | --- | --- | --- |"]
        for name, d in r["summary"][split]["exact_all"].items():
            L.append(f"| {name} | {format_number(d['rmse']['median'], '.3f')} | {format_number(d['rmse']['mean'], '.3f')} | {format_number(d['rmse']['max'], '.3f')} | "
                     f"{format_number(d['excess_over_oracle']['mean'], '.4f')} | {format_number(d['excess_over_oracle']['max'], '.3f')} | "
                     f"{100 * d['agreement_with_oracle']:.1f} % |")
        L.append("")
    L += ["## The proposed selector (predicted-error)", "",
          "Predicts, from the bracket's DN histogram alone, the mean squared emulation error of each bracket: "
          "quantisation (the source DN's exposure interval mapped through the ratio), the source's noise carried "
          "through the mapping (noise model of the camera), and clipped source pixels that the ratio does not "
          f"preserve, weighted by a clip weight tuned on the training scenes (chosen: {pe['clip_weight']:g}).", "",
          f"Beats HigherNoSat on the held-out scenes ({pe['criterion']}): **{pe['beats_higher_no_sat_on_held_out']}**.",
          "", "## Figures", ""] + [f"![{f}]({f})" for f in figures]
    return "\n".join(L) + "\n"


# ------------------------------------------------------------------------------------------ motion
_SOURCE_TITLE = {"mitsuba": "rendered forest scenes (walk)", "chart": "translating chart (exact)"}


def _motion_figures(out: dict, folder: Path) -> list[str]:
    r, a = out["results"], out["arrays"]
    sources = list(r["sources"])
    fig, axes = subplots(1, len(sources) + 1, figsize=(5.5 * (len(sources) + 1), 4.2))
    axes = np.atleast_1d(axes)
    for ax, source in zip(axes, sources):
        d = r["sources"][source]
        for n_i, (v, table) in enumerate(d["by_speed_and_offset"].items()):
            offs = sorted(table, key=int)
            x = [table[o]["offset_ms"] for o in offs]
            ax.plot(x, [table[o]["clean_all"]["median"] for o in offs], "o-", color=f"C{n_i}", label=f"{v} m/s")
            if source == "mitsuba":
                y = [table[o]["clean_all_floor_subtracted"]["median"] for o in offs]
                ax.plot(x, [np.nan if v_ is None else v_ for v_ in y], "x--", color=f"C{n_i}", lw=0.8)
        floor = d["render_noise_floor_all"]["median"]
        if floor is not None:
            ax.axhline(floor, color="0.5", ls=":", lw=1, label="render-noise floor (other seed)")
        ax.set_xlabel("bracket time - target time (ms)")
        ax.set_ylabel("median RMSE (% of DN range), all pixels")
        ax.set_title(_SOURCE_TITLE.get(source, source) + ("\n(dashed: floor subtracted)" if source == "mitsuba"
                                                           else ""), fontsize=9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    ax = axes[-1]
    for is_chart, marker, label in ((False, "o", "rendered"), (True, "^", "chart")):
        m = a["is_chart"] == is_chart
        if m.any():
            sc = ax.scatter(a["displacement_m"][m], a["clean_all"][m], c=a["speed_mps"][m], s=12, marker=marker,
                            cmap="viridis", label=label, vmin=min(r["config"]["speeds_mps"]),
                            vmax=max(r["config"]["speeds_mps"]))
    fig.colorbar(sc, ax=ax, label="speed (m/s)")
    ax.set_xlabel("camera displacement between bracket and target (m)")
    ax.set_ylabel("RMSE (% of DN range), all pixels")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, folder / "motion_error.png", dpi=110)
    return ["motion_error.png"]


def _motion_md(r: dict, figures: list[str]) -> str:
    cfg = r["config"]
    L = ["# Motion between brackets", "", r["method"] + ".", "",
         f"Rendered scenes: {', '.join(cfg['scenes']) or 'none'} ({cfg['width']}x{cfg['height']} at {cfg['spp']} spp, "
         f"{r['renders']} renders); chart: {cfg['chart']} (depth {cfg['chart_depth_m']:g} m); speeds "
         f"{', '.join(f'{v:g}' for v in cfg['speeds_mps'])} m/s; shot instants "
         f"{', '.join(f'{t:g}' for t in cfg['shot_times_s'])} s; targets {', '.join(f'{t:g}' for t in cfg['targets_ms'])}"
         " ms. Errors: % of the DN range, all pixels, noiseless captures, median over targets, shot instants, scenes "
         "and both signs of the offset. Small images: the same displacement shifts a full 1920x1200 frame "
         f"{1920 / cfg['width']:.0f} times more pixels, so these figures understate full-frame errors.", ""]
    for source, d in r["sources"].items():
        first = next(iter(d["by_speed_and_abs_offset"].values()))
        L += [f"## {_SOURCE_TITLE.get(source, source)}", "",
              f"Static baseline (offset 0): median {format_number(d['static_baseline_clean_all']['median'], '.3f')} %; one shot away "
              f"(45 ms): median {format_number(d['one_shot_offset_clean_all']['median'], '.3f')} %; largest offset: median "
              f"{format_number(d['largest_offset_clean_all']['median'], '.3f')} %, max {format_number(d['largest_offset_clean_all']['max'], '.3f')} %"
              + (f"; floor-subtracted median {format_number(d['largest_offset_floor_subtracted']['median'], '.3f')} %; render-noise "
                 f"floor median {format_number(d['render_noise_floor_all']['median'], '.3f')} %" if source == "mitsuba" else "")
              + f"; least-squares growth {format_number(d['error_per_metre_percent'], '.3f')} % per metre.", "",
              "| speed (m/s) | " + " | ".join(f"{x['offset_ms']:.0f} ms" for x in first.values()) + " |",
              "| --- |" + " --- |" * len(first)]
        for v, row in d["by_speed_and_abs_offset"].items():
            cells = []
            for x in row.values():
                c = format_number(x["median_clean_all"], '.3f')
                if source == "mitsuba" and x["median_clean_all_floor_subtracted"] is not None:
                    c += f" ({format_number(x['median_clean_all_floor_subtracted'], '.3f')})"
                if source == "chart" and x["shift_px"] is not None:
                    c += f" [{x['shift_px']:.2f} px]"
                cells.append(c)
            L.append(f"| {v} | " + " | ".join(cells) + " |")
        L += ["", "(parentheses: render-noise floor subtracted in quadrature)"
              if source == "mitsuba" else "(brackets: image shift in pixels)", ""]
    L += ["## Figures", ""] + [f"![{f}]({f})" for f in figures]
    return "\n".join(L) + "\n"


# ------------------------------------------------------------------------------------------ speed
def _speed_figures(out: dict, folder: Path) -> list[str]:
    r = out["results"]
    fig, ax = subplots(figsize=(7.5, 4.5))
    for row in r["table"]:
        t = row.get("ms_per_full_frame", row["ms_per_study_image"])
        y = row["rmse_all"]["median"]
        marker = "o" if row["kind"] == "emulation" else "s"
        ax.plot([t], [y], marker, ms=8)
        ax.annotate(row["config"], (t, y), textcoords="offset points",
                    xytext=(5, -12) if row["config"] == "lut+build" else (5, 4), fontsize=8)
    ax.set_xscale("log")
    ax.set_yscale("symlog", linthresh=0.01)
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("time per image (ms): emulation per 1920x1200 frame, render per study-size image")
    ax.set_ylabel("median RMSE (% of DN range)")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    save_figure(fig, folder / "speed_vs_error.png", dpi=110)
    return ["speed_vs_error.png"]


def _speed_md(r: dict, figures: list[str]) -> str:
    h, w = r["full_frame"]
    sh, sw = r["study_size"]
    L = ["# Speed against error", "", r["note"] + ".", "",
         f"| configuration | ms per {w}x{h} frame | ms per {sw}x{sh} image | median RMSE (all) | max RMSE (all) | "
         "median RMSE (valid) |", "| --- | --- | --- | --- | --- | --- |"]
    for row in r["table"]:
        full = row.get("ms_per_full_frame")
        valid = row.get("rmse_valid", {}).get("median") if "rmse_valid" in row else None
        L.append(f"| {row['config']} | {format_number(full, '.2f') if full is not None else '-'} | "
                 f"{format_number(row['ms_per_study_image'], '.3f')} | {format_number(row['rmse_all']['median'], '.4f')} | "
                 f"{format_number(row['rmse_all']['max'], '.4f')} | {format_number(valid, '.4f') if valid is not None else '-'} |")
    L += ["", f"Render rows: RMSE of noiseless captures against those of a {r['reference_spp']}-spp render.", "",
          "## Figures", ""] + [f"![{f}]({f})" for f in figures]
    return "\n".join(L) + "\n"
