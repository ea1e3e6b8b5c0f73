"""Running the AE study: synthesise, play back, benchmark, summarise, report; and redrawing it."""

from __future__ import annotations

import shutil
import sys
import time
from dataclasses import asdict
from pathlib import Path

from emulator.cells import format_number
from emulator.io.files import REPORT_FILE, RESULTS_FILE, prepare_output, read_results, write_results, write_text
from emulator.report.html import run_folder_pages, write_report
from validation.ae_study.config import CONFIGS, PAPER, VO_CONFIGURATION_NOTE, StudyConfig, StudyError, config_from_dict
from validation.ae_study.findings import evaluate_findings, findings_paragraph, findings_with_evidence
from validation.ae_study.report import method_intervals, method_intervals_markdown, plot_summary, report_markdown
from validation.ae_study.summary import summarise
from validation.verdicts.findings import FAMILY

__all__ = ["REPLICATES_DIR", "run_study", "run_replicated_study", "finish_replicated_study", "redraw"]

#: Sub-folder of :func:`run_replicated_study`'s studies, one per seed.
REPLICATES_DIR = "replicates"


def _bar(total: int, desc: str, unit: str, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=not enabled, file=sys.stderr, leave=False)


def _callback(bar):
    def cb(done, total):
        bar.total = total
        bar.n = done
        bar.refresh()

    return cb


def run_study(out, config: StudyConfig = CONFIGS["full"], *, force: bool = False, progress: bool = True,
              command: str | None = None, cache_dir=None, scheduler: str | None = None) -> dict:
    """Run the study into folder ``out`` (layout in the module docstring); returns results.json's content.

    Parameters
    ----------
    out : path
        Output folder.  A folder holding ``results.json`` is refused unless ``force``.  A
        folder without it (an interrupted study) is reused: the sub-folders the study writes
        (``datasets/<scene>``, ``runs/<scene>``, ``features``, ``vo/<scene>``) are recomputed;
        renders come from the render cache.
    config : StudyConfig
    force : bool
        Overwrite an existing study.
    progress : bool
        tqdm progress bars on stderr.
    command : str, optional
        The command line, recorded.
    cache_dir : None, path or False
        Render cache (see :func:`scenes.render`).
    scheduler : None, "local" or "tcp://HOST:PORT"
        Render every shot of the walks as Dask tasks first (:func:`scenes.synthesize.synthesize`):
        the same cache entries and recordings as serial.

    Raises
    ------
    emulator.errors.OutputExistsError
        ``out/results.json`` exists and ``force`` is not given.
    """
    import scenes
    from emulator.io.borealhdr import load_sequence
    from emulator.metrics.bench import bench_features, bench_vo
    from emulator.metrics.features import DEFAULT_TAUS
    from emulator.metrics.vo import VOParameters
    from emulator.playback import RunConfig
    from emulator.orchestration.runner import run_to_folder
    from scenes.synthesize import synthesize

    out = prepare_output(out, force=force)
    cfg = config
    timings: dict[str, float] = {}
    t_start = time.perf_counter()
    run_dirs, runs = {}, {}
    for k, scene_name in enumerate(cfg.scenes):
        scene = scenes.get_scene(scene_name, seed=cfg.scene_seed, **cfg.scene_parameters(scene_name))
        ds = out / "datasets" / scene_name
        run_dir = out / "runs" / scene_name
        for folder in (ds, run_dir):
            if folder.exists():
                shutil.rmtree(folder)
        t0 = time.perf_counter()
        with _bar(cfg.n_cycles * 6, f"[{k + 1}/{len(cfg.scenes)}] synthesise {scene_name}", "shot", progress) as bar:
            synthesize(scene, ds, n_cycles=cfg.n_cycles, width=cfg.width, height=cfg.height, spp=cfg.spp,
                       stereo=True, seed=cfg.camera_seed, render_seed=cfg.render_seed, cache_dir=cache_dir,
                       progress=_callback(bar), scheduler=scheduler)
        timings[f"synthesise_{scene_name}_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        seq = load_sequence(ds)
        with _bar(len(seq), f"[{k + 1}/{len(cfg.scenes)}] closed loop {scene_name}, 7 methods", "cycle",
                  progress) as bar:
            runs[scene_name] = run_to_folder(seq, "all", run_dir, RunConfig(save="png16", initial_ms=cfg.initial_ms),
                                             progress=_callback(bar), command=command)
        timings[f"closed_loop_{scene_name}_s"] = time.perf_counter() - t0
        run_dirs[scene_name] = run_dir

    t0 = time.perf_counter()
    taus = sorted(set(int(t) for t in DEFAULT_TAUS) | set(int(t) for t in cfg.taus))
    features = bench_features([run_dirs[s] for s in cfg.scenes], out / "features", taus=taus,
                              seed=cfg.features_seed, force=True, progress=progress, command=command)
    timings["features_s"] = time.perf_counter() - t0
    vo = {}
    params = VOParameters(ratio=cfg.vo_ratio, seed=cfg.vo_seed)
    for scene_name in cfg.scenes:
        t0 = time.perf_counter()
        vo[scene_name] = bench_vo(run_dirs[scene_name], out / "vo" / scene_name, parameters=params,
                                  rpe_on_failure=True, force=True, progress=progress, command=command)
        timings[f"vo_{scene_name}_s"] = time.perf_counter() - t0
    summary = summarise(cfg, features, vo, runs)
    findings = findings_with_evidence(summary, evaluate_findings(summary, cfg.taus), cfg.taus, seed=cfg.scene_seed)
    timings["total_s"] = time.perf_counter() - t_start
    from emulator import __version__

    results = {
        "study": "ae_study",
        "exposim_version": __version__,
        "command": command,
        "config": cfg.to_dict(),
        "render_variant": scenes.choose_variant(),
        "vo_parameters": asdict(params),
        "vo_configuration_note": VO_CONFIGURATION_NOTE,
        "paper": PAPER,
        "summary": summary,
        "findings": findings,
        "findings_paragraph": findings_paragraph(findings),
        "timings": timings,
        "files": {
            "report": "report.md",
            "summary_figure": "ae_study_summary.png",
            "features": "features/results.json",
            "vo": {s: f"vo/{s}/results.json" for s in cfg.scenes},
            "runs": {s: f"runs/{s}" for s in cfg.scenes},
            "datasets": {s: f"datasets/{s}" for s in cfg.scenes},
        },
    }
    plot_summary(results, out / "ae_study_summary.png")
    write_report(out, report_markdown(results), sheets=[run_folder_pages(
        out, [(s, out / "runs" / s) for s in cfg.scenes], n_sheets=len(cfg.scenes))])
    write_results(out / RESULTS_FILE, results)
    return results


def run_replicated_study(out, config: StudyConfig = CONFIGS["full"], replicates: int = 1, *, force: bool = False,
                         command: str | None = None, **kwargs) -> dict:
    """The study on ``replicates`` seeds: replicate ``k`` adds ``k`` to the scene, camera and render seeds, so
    each scene of each replicate is an independent walk (issue 22); the findings are judged over all walks.

    Replicate ``k`` is a complete study in ``out/replicates/seed<scene_seed + k>``; ``out/results.json``
    and ``out/report.md`` hold the findings over every walk (:func:`finish_replicated_study`).
    ``kwargs`` go to :func:`run_study`.
    """
    from dataclasses import replace

    if replicates < 1:
        raise StudyError(f"replicates must be >= 1, got {replicates}")
    out = prepare_output(out, force=force)
    studies = []
    for k in range(replicates):
        cfg = replace(config, scene_seed=config.scene_seed + k, camera_seed=config.camera_seed + k,
                      render_seed=config.render_seed + k)
        studies.append(run_study(out / REPLICATES_DIR / f"seed{cfg.scene_seed}", cfg, force=force, command=command,
                                 **kwargs))
    return finish_replicated_study(out, studies, command=command)


def finish_replicated_study(out, studies: list[dict], command: str | None = None) -> dict:
    """``results.json`` and ``report.md`` of the findings over the walks of several studies' results."""
    out = Path(out)
    per_scene = {f"{scene}/seed{st['config']['scene_seed']}": rows for st in studies
                 for scene, rows in st["summary"]["per_scene"].items()}
    first = studies[0]
    pooled = {"per_scene": per_scene, "overall": first["summary"]["overall"]}
    taus = first["config"]["taus"]
    findings = findings_with_evidence(pooled, first["findings"], taus, seed=first["config"]["scene_seed"])
    for f in findings:
        f["point_comparison_of"] = f"{REPLICATES_DIR}/seed{first['config']['scene_seed']}"
    results = {"study": "ae_study, replicated", "command": command, "config": first["config"],
               "replicates": [f"{REPLICATES_DIR}/seed{st['config']['scene_seed']}" for st in studies],
               "walks": list(per_scene), "n_walks": len(per_scene), "findings": findings,
               "findings_paragraph": findings_paragraph(findings),
               "timings": {"total_s": float(sum(st["timings"].get("total_s", 0.0) for st in studies))}}
    lines = ["# Synthetic AE study, replicated", "",
             f"{len(studies)} replicate(s), {len(per_scene)} walks ({', '.join(per_scene)}). Command: `{command}`", "",
             results["findings_paragraph"], "",
             "| finding | verdict | effect | 95 % interval | adjusted p | walks | effect definition |",
             "| --- | --- | ---: | --- | ---: | ---: | --- |"]
    for f in findings:
        ci = f.get("ci95") or [None, None]
        lines.append(f"| {f['id']} | {f['verdict']} | {format_number(f['effect'])} | {format_number(ci[0])}..{format_number(ci[1])} | "
                     f"{format_number(f['p_adjusted'], '.2g')} | {f.get('n_walks') if f.get('n_walks') is not None else '-'} | "
                     f"{f.get('effect_definition') or f.get('verdict_reason')} |")
    lines += ["", f"Each claim is tested as stated (every comparison it needs must reject). Family: {FAMILY}."]
    results["method_intervals"] = method_intervals(per_scene)
    lines += [""] + method_intervals_markdown(per_scene)
    write_report(out, "\n".join(lines) + "\n")
    write_results(out / RESULTS_FILE, results)
    return results


def redraw(out) -> dict:
    """Re-summarise, re-evaluate the findings and rewrite ``report.md``, the summary figure
    and ``results.json`` from the benchmarks' stored results (``features/``, ``vo/<scene>/``,
    ``runs/<scene>/results.json``); nothing is rendered, played back or measured again.

    Raises
    ------
    StudyError
        When ``out/results.json`` or a benchmark's results do not exist.
    """
    out = Path(out)
    path = out / "results.json"
    reps = out / REPLICATES_DIR
    if reps.is_dir():  # a replicated study: redraw each replicate, then the findings over all walks
        studies = [redraw(p) for p in sorted(reps.iterdir()) if (p / "results.json").is_file()]
        if studies:
            command = read_results(path).get("command") if path.is_file() else None
            return finish_replicated_study(out, studies, command=command)
    if not path.is_file():
        raise StudyError(f"{path}: no study to redraw")
    results = read_results(path)
    cfg = config_from_dict(results["config"])
    try:
        features = read_results(out / "features")
        vo = {s: read_results(out / "vo" / s) for s in cfg.scenes}
        runs = {s: read_results(out / "runs" / s) for s in cfg.scenes}
    except FileNotFoundError as exc:
        raise StudyError(f"{out}: cannot redraw: {exc}") from None
    results["config"] = cfg.to_dict()
    results["vo_configuration_note"] = VO_CONFIGURATION_NOTE
    results["summary"] = summarise(cfg, features, vo, runs)
    results["findings"] = findings_with_evidence(
        results["summary"], evaluate_findings(results["summary"], results["config"]["taus"]),
        results["config"]["taus"], seed=cfg.scene_seed)
    results["findings_paragraph"] = findings_paragraph(results["findings"])
    results["redrawn"] = results.get("redrawn", 0) + 1
    plot_summary(results, out / "ae_study_summary.png")
    write_report(out, report_markdown(results), sheets=[run_folder_pages(
        out, [(s, out / "runs" / s) for s in cfg.scenes], n_sheets=len(cfg.scenes))])
    write_results(path, results)
    return results
