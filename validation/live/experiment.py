"""Run the experiment into a folder, and redraw its verdicts from the raw record.

:func:`run_live_experiment` records the walks, runs the emulated and live loops, compares
them, writes the run folders and benchmarks them, measures the noise variance ratio, and
writes ``raw.json``; :func:`finish` turns that record into ``results.json``, ``report.md``
and the figures (:func:`redraw` does it again from ``raw.json`` alone).  All files go
through :mod:`emulator.io`.
"""

from __future__ import annotations

import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from emulator.playback import RunConfig
from emulator.io.files import REPORT_FILE, RESULTS_FILE, first_free, read_results, to_jsonable, write_results, write_text
from emulator.report.html import write_report
from validation.live.compare import exposure_log2_errors, image_errors, measure_noise_variance_ratio
from validation.live.config import (
    BRIGHTENING_PAIRS,
    CONFIGS,
    CONTROL,
    NOISE_OPTIONS,
    VARIANTS,
    LiveConfig,
    LiveError,
    config_from_dict,
)
from validation.live.loops import DatasetRadiance, iter_emulated, iter_live, write_run_folder
from validation.live.report import plot_metrics, plot_trajectories, report_markdown
from validation.live.verdicts import assemble, ratio_use

__all__ = ["RAW_FILE", "REPLICATES_DIR", "NATIVE_RUN", "numbered_output", "run_live_experiment", "finish", "evidence",
           "run_replicated", "finish_replicated", "redraw"]

#: What :func:`redraw` recomputes the verdicts from (per-cycle comparisons, benchmark summaries).
RAW_FILE = "raw.json"
#: Sub-folder of :func:`run_replicated`'s experiments, one per seed.
REPLICATES_DIR = "replicates"
#: Run name of the native-rate live condition (``native_loop``).
NATIVE_RUN = "live-native"


def numbered_output(out) -> Path:
    """``out`` if it does not exist or is empty, else the first free ``out-2``, ``out-3`` ... (never overwrite)."""
    out = Path(out)
    if not out.exists() or (out.is_dir() and not any(out.iterdir())):
        return out
    return first_free(out)


def _bar(total: int, desc: str, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, disable=not enabled, file=sys.stderr, leave=False)


def _runs_summary(cycles, names) -> dict:
    out = {}
    for name in names:
        t = [cs.steps[name].target_ms for cs in cycles if name in cs.steps]
        s = [cs.steps[name].saturated_fraction for cs in cycles if name in cs.steps]
        out[name] = {"median_exposure_ms": float(np.median(t)) if t else None,
                     "mean_saturated_fraction": float(np.mean(s)) if s else None}
    return {"methods": out}


def run_live_experiment(out, config: LiveConfig | None = None, *, progress: bool = True, command: str | None = None,
                        cache_dir=None, log: Callable[[str], None] | None = None,
                        scheduler: str | None = None, native_loop: Callable | None = None) -> dict:
    """Run the experiment into ``out`` (a new or empty folder; see :func:`numbered_output`).

    ``config`` defaults to ``CONFIGS["full"]``.  ``scheduler`` (``"local"`` or
    ``"tcp://HOST:PORT"``) renders every shot of the walks as Dask tasks first
    (:func:`scenes.synthesize.synthesize`; the same recordings as serial).  Returns the
    content of ``results.json``.

    ``native_loop``: the native-rate live condition (issue 22), a callable
    ``native_loop(sequence, radiance, camera, methods, *, seed, noise, initial_ms, selector,
    response)`` yielding :class:`emulator.playback.CycleStep` per cycle with images kept (a
    camera at the recorder's frame rate with an exposure latency, the same closed loop as
    ``exposim run``); its run is ``live-native``.  Default (None):
    :func:`validation.live.native.native_rate_loop` at ``config.frame_rate_hz`` with
    ``config.latency_frames``, when ``config.native`` (else that condition is reported as
    not run in results.json ``conditions`` and ``comparisons``).
    """
    import scenes
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.errors import OutputExistsError
    from emulator.noise import NoiseModel
    from scenes.synthesize import synthesize
    from synth.noise_model import noise_model_of
    from synth.sequence import load_camera
    from validation import ae_study

    cfg = CONFIGS["full"] if config is None else config
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise OutputExistsError(f"{out}: exists and is not empty; refusing to overwrite (choose another folder)")
    out.mkdir(parents=True, exist_ok=True)
    say = log or (lambda msg: None)
    names = list(cfg.methods)
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    run_names = [f"emulated-{n}" for n in NOISE_OPTIONS] + [f"live-{v}" for v in VARIANTS]
    if cfg.control:
        run_names.append(f"live-{CONTROL}")
    if native_loop is None and cfg.native:
        from functools import partial

        from validation.live.native import native_rate_loop

        native_loop = partial(native_rate_loop, latency_frames=cfg.latency_frames, frame_rate_hz=cfg.frame_rate_hz)
    if native_loop is not None:
        run_names.append(NATIVE_RUN)
    per_scene: dict = {}
    run_summaries: dict = {r: {} for r in run_names}
    ratio_input = None
    for k, scene_name in enumerate(cfg.scenes):
        tag = f"[{k + 1}/{len(cfg.scenes)}] {scene_name}"
        scene = scenes.get_scene(scene_name, seed=cfg.seed, **cfg.scene_parameters(scene_name))
        ds = out / "datasets" / scene_name
        t0 = time.perf_counter()
        with _bar(cfg.n_cycles * 6, f"{tag}: render + record", progress) as bar:
            synthesize(scene, ds, n_cycles=cfg.n_cycles, width=cfg.width, height=cfg.height, spp=cfg.spp, stereo=True,
                       seed=cfg.seed, render_seed=cfg.seed, noise=cfg.capture_noise, save_radiance=True,
                       render_per=cfg.render_per,
                       cache_dir=cache_dir, progress=lambda d, n: bar.update(d - bar.n), scheduler=scheduler)
        timings[f"record_{scene_name}_s"] = time.perf_counter() - t0
        say(f"{tag}: recorded {cfg.n_cycles} cycles in {timings[f'record_{scene_name}_s']:.0f} s")
        seq = load_sequence(ds)
        response = sequence_response(seq)
        camera = load_camera(ds)
        synth_model = noise_model_of(camera)
        model = NoiseModel(response, synth_model.gain_e_per_h, synth_model.read_noise_e, synth_model.name)
        radiance = DatasetRadiance(ds)
        if ratio_input is None:
            first = seq.cycles[0].frames["left"][seq.cycles[0].available(("left",))[0]].timestamp_ns
            ratio_input = (radiance(first, "left"), camera, response, model)
        from scenes.walkshots import walk_radiance  # live shots blurred over their own windows (issue 21)

        radiance = walk_radiance(ds, scene, cache_dir=cache_dir) or radiance
        common = dict(config=RunConfig(initial_ms=cfg.initial_ms, selector=cfg.selector), response=response)
        cycles: dict = {}
        t0 = time.perf_counter()
        for opt, mode in NOISE_OPTIONS.items():
            with _bar(len(seq.cycles), f"{tag}: emulated loop ({opt})", progress) as bar:
                got = []
                for cs in iter_emulated(seq, names, noise=mode, noise_model=model, seed=cfg.seed, **common):
                    got.append(cs)
                    bar.update(1)
            cycles[f"emulated-{opt}"] = got
        timings[f"emulated_{scene_name}_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        live_runs = [(v, v, cfg.seed) for v in VARIANTS]
        if cfg.control:
            live_runs.append((CONTROL, "same-instant", cfg.seed + 1))
        for label, timing, seed in live_runs:
            with _bar(len(seq.cycles), f"{tag}: live loop ({label})", progress) as bar:
                got = []
                for cs in iter_live(seq, radiance, camera, names, timing=timing, noise=cfg.capture_noise, seed=seed,
                                    **common):
                    got.append(cs)
                    bar.update(1)
            cycles[f"live-{label}"] = got
        if native_loop is not None:
            with _bar(len(seq.cycles), f"{tag}: live loop (native rate)", progress) as bar:
                got = []
                for cs in native_loop(seq, radiance, camera, names, seed=cfg.seed, noise=cfg.capture_noise,
                                      initial_ms=cfg.initial_ms, selector=cfg.selector, response=response):
                    got.append(cs)
                    bar.update(1)
            cycles[NATIVE_RUN] = got
        timings[f"live_{scene_name}_s"] = time.perf_counter() - t0
        # comparisons (images in memory), then the run folders
        comp: dict = {}
        for opt in NOISE_OPTIONS:
            for v in VARIANTS + ((CONTROL,) if cfg.control else ()):
                emu, lv = cycles[f"emulated-{opt}"], cycles[f"live-{v}"]
                err = exposure_log2_errors(emu, lv, names)
                img = image_errors(emu, lv, names, seq, response)
                comp[f"{opt}/{v}"] = {m: {"exposure_log2_error": err[m], **img[m]} for m in names}
        if cfg.control:
            a, b = cycles["live-same-instant"], cycles[f"live-{CONTROL}"]
            err = exposure_log2_errors(a, b, names)
            comp["live/control"] = {m: {"exposure_log2_error": err[m]} for m in names}
        for r in run_names:
            write_run_folder(out / "runs" / scene_name / r, ds, cycles[r], names, white_level=seq.white_level,
                             black_level=seq.black_level, description={"run": r, "scene": scene_name})
            run_summaries[r][scene_name] = _runs_summary(cycles[r], names)
        trajectories = {r: {m: {"timestamp_ns": [cs.steps[m].timestamp_ns for cs in cycles[r] if m in cs.steps],
                                "target_ms": [cs.steps[m].target_ms for cs in cycles[r] if m in cs.steps],
                                "bracket_ms": [cs.steps[m].bracket_ms for cs in cycles[r] if m in cs.steps]}
                            for m in names} for r in run_names}
        per_scene[scene_name] = {"comparison": comp, "trajectories": trajectories}
        del cycles
        if not cfg.keep_radiance:
            shutil.rmtree(ds / "ground_truth" / "radiance", ignore_errors=True)

    t0 = time.perf_counter()
    nvr = measure_noise_variance_ratio(*ratio_input, repeats=cfg.noise_repeats, seed=cfg.seed)
    nvr["input"] = f"first left radiance of {cfg.scenes[0]}"
    nvr_up = measure_noise_variance_ratio(*ratio_input, repeats=cfg.noise_repeats, seed=cfg.seed,
                                          pairs=BRIGHTENING_PAIRS)
    nvr_up["input"] = nvr["input"]
    timings["noise_ratio_s"] = time.perf_counter() - t0

    summaries, findings = {}, {}
    if cfg.metrics:
        from emulator.metrics.bench import bench_features, bench_vo
        from emulator.metrics.features import DEFAULT_TAUS
        from emulator.metrics.vo import VOParameters

        study_cfg = ae_study.StudyConfig(scenes=tuple(cfg.scenes), n_cycles=cfg.n_cycles, width=cfg.width,
                                         height=cfg.height, spp=cfg.spp, vo_ratio=cfg.vo_ratio,
                                         segment_pairs=cfg.segment_pairs, taus=tuple(cfg.taus))
        taus = sorted(set(int(t) for t in DEFAULT_TAUS) | set(int(t) for t in cfg.taus))
        params = VOParameters(ratio=cfg.vo_ratio, seed=cfg.seed)
        for r in run_names:
            t0 = time.perf_counter()
            say(f"metrics: {r}")
            feats = bench_features([out / "runs" / s / r for s in cfg.scenes], out / "features" / r, taus=taus,
                                   seed=cfg.seed, progress=progress, command=command)
            vo = {s: bench_vo(out / "runs" / s / r, out / "vo" / s / r, parameters=params, rpe_on_failure=True,
                              progress=progress, command=command) for s in cfg.scenes}
            summaries[r] = ae_study.summarise(study_cfg, feats, vo, run_summaries[r])
            findings[r] = ae_study.evaluate_findings(summaries[r], cfg.taus)
            timings[f"metrics_{r}_s"] = time.perf_counter() - t0

    timings["total_s"] = time.perf_counter() - t_start
    from emulator import __version__

    raw = {"config": cfg.to_dict(), "command": command, "exposim_version": __version__,
           "render_variant": scenes.choose_variant(), "timings": timings, "per_scene": to_jsonable(per_scene),
           "summaries": summaries, "findings": findings, "noise_variance_ratio": nvr,
           "noise_variance_ratio_brightening": nvr_up}
    write_results(out / RAW_FILE, raw, overwrite=False)
    return finish(out, raw)


def _brightening_on_chart(dataset: Path, cfg: LiveConfig) -> dict:
    """The brightening noise variance ratio on an HDR chart through the recording's camera."""
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.noise import NoiseModel
    from synth.noise_model import noise_model_of
    from synth.procedural import hdr_chart
    from synth.sequence import load_camera

    camera = load_camera(dataset)
    response = sequence_response(load_sequence(dataset))
    m = noise_model_of(camera)
    model = NoiseModel(response, m.gain_e_per_h, m.read_noise_e, m.name)
    chart = hdr_chart(camera.width, camera.height, seed=cfg.seed, dynamic_range_db=60.0,
                      max_radiance=float(camera.full_well_e / camera.radiance_scale / 2.0))
    res = measure_noise_variance_ratio(chart, camera, response, model, repeats=cfg.noise_repeats, seed=cfg.seed,
                               pairs=BRIGHTENING_PAIRS)
    res["input"] = "hdr_chart (60 dB) through the recording's camera"
    return res


def finish(out, raw: dict) -> dict:
    """Verdicts, figures, ``report.md`` and ``results.json`` from the raw record (see :func:`redraw`)."""
    out = Path(out)
    cfg = config_from_dict(raw["config"])
    per_scene = raw["per_scene"]
    for sc in per_scene.values():
        for comp in sc["comparison"].values():
            for m, d in comp.items():
                for k in list(d):
                    d[k] = np.asarray(d[k], dtype=np.float64)
    nvr_up = raw.get("noise_variance_ratio_brightening")
    if nvr_up is None:  # a record from before this measurement: measure it on a chart with the run's camera
        nvr_up = _brightening_on_chart(out / "datasets" / cfg.scenes[0], cfg)
    results = assemble(cfg, per_scene, raw["summaries"], raw["findings"], raw["noise_variance_ratio"],
                       list(cfg.methods))
    results.update(evidence(cfg, [raw]))
    results["noise_variance_ratio_brightening"] = {"plain": nvr_up["plain"], "consistent": nvr_up["consistent"]}
    results["noise_variance_ratio_brightening_detail"] = nvr_up
    results["emulation_ratio_use"] = ratio_use(per_scene, list(cfg.methods))
    results.update({
        "experiment": "live versus emulated",
        "exposim_version": raw.get("exposim_version"),
        "command": raw.get("command"),
        "config": cfg.to_dict(),
        "render_variant": raw.get("render_variant"),
        "timings": raw.get("timings", {}),
        "files": {"report": "report.md", "metrics_figure": "metrics.png" if cfg.metrics else None,
                  "exposure_figures": {s: f"exposure_{s}.png" for s in cfg.scenes}, "raw": RAW_FILE,
                  "runs": "runs/<scene>/<run>", "features": "features/<run>", "vo": "vo/<scene>/<run>"},
    })
    for s in cfg.scenes:
        plot_trajectories(per_scene[s]["trajectories"], out / f"exposure_{s}.png", title=s)
    if cfg.metrics:
        plot_metrics(results, out / "metrics.png")
    write_report(out, report_markdown(results), sheets=[_live_sheets(out, cfg.scenes[0])])
    write_results(out / RESULTS_FILE, results)
    return results


def evidence(cfg: LiveConfig, records: list[dict], power_seeds: int = 100) -> dict:
    """results.json's replicated verdicts (:func:`validation.live.evidence.judge_metrics`) over the walks of
    ``records`` (one experiment, or the replicates of :func:`run_replicated`)."""
    from validation.live.evidence import judge_metrics, walk_values

    walks, tables = walk_values(records, cfg.methods)
    out = {"walks": walks, "n_walks": len(walks)}
    if tables:
        out.update(judge_metrics(tables, cfg.methods, seed=cfg.seed, power=power_seeds > 0, power_seeds=power_seeds))
        out["n_walks"] = len(walks)
    else:
        out.update({"metrics": {}, "reason": "no benchmark metrics in this experiment (metrics off)"})
    return out


def run_replicated(out, config: LiveConfig | None = None, replicates: int = 1, *, command: str | None = None,
                   **kwargs) -> dict:
    """The experiment on ``replicates`` seeds (``config.seed``, ``+1``, ...), each scene of each one an
    independent walk; the verdicts over all of them.

    Each replicate is a complete experiment in ``out/replicates/seed<S>`` (its own
    results.json over its scenes); ``out/results.json`` and ``out/report.md`` hold the
    verdicts over every walk (:func:`finish_replicated`).  ``kwargs`` go to
    :func:`run_live_experiment`.
    """
    from dataclasses import replace

    from emulator.errors import OutputExistsError

    cfg = CONFIGS["full"] if config is None else config
    if replicates < 1:
        raise LiveError(f"replicates must be >= 1, got {replicates}")
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise OutputExistsError(f"{out}: exists and is not empty; refusing to overwrite (choose another folder)")
    records = []
    for k in range(replicates):
        sub = out / REPLICATES_DIR / f"seed{cfg.seed + k}"
        run_live_experiment(sub, replace(cfg, seed=cfg.seed + k), command=command, **kwargs)
        records.append(read_results(sub / RAW_FILE))
    return finish_replicated(out, records, command=command)


def finish_replicated(out, records: list[dict], command: str | None = None, power_seeds: int = 100) -> dict:
    """``results.json`` and ``report.md`` of the verdicts over the replicates' walks (``power_seeds``:
    simulated studies per point of the power functions)."""
    from validation.live.report import evidence_markdown

    out = Path(out)
    cfg = config_from_dict(records[0]["config"])
    results = {"experiment": "live versus emulated, replicated", "command": command,
               "config": cfg.to_dict(), "replicates": [f"{REPLICATES_DIR}/seed{r['config']['seed']}" for r in records],
               "timings": {"total_s": float(sum((r.get("timings") or {}).get("total_s", 0.0) for r in records))}}
    results.update(evidence(cfg, records, power_seeds=power_seeds))
    write_report(out, "# Live versus emulated, replicated\n\n"
                 + f"{len(records)} replicate(s) of the experiment (seeds "
                 + ", ".join(str(r["config"]["seed"]) for r in records) + f"), {results['n_walks']} walks. "
                 + f"Command: `{command}`\n\n" + evidence_markdown(results))
    write_results(out / RESULTS_FILE, results)
    return results


def _live_sheets(out: Path, scene: str) -> str:
    """Contact sheets of the first scene: what each method saw in every run (emulated and live)."""
    from emulator.io.runfolder import read_run_json, read_tables
    from emulator.report.html import run_contact_sheet

    parts = []
    folder = Path(out) / "runs" / scene
    for run_dir in sorted(p for p in folder.glob("*") if (p / "run.json").is_file()):
        info = read_run_json(run_dir)
        sheet = run_contact_sheet(run_dir, info["methods"], read_tables(run_dir, info["methods"]),
                                  white_level=info.get("white_level"))
        parts.append(sheet.replace("What each method saw", f"{scene}, {run_dir.name}: what each method saw", 1))
    return "\n".join(parts)


def redraw(out) -> dict:
    """Recompute the verdicts and rewrite ``results.json``, ``report.md`` and the figures of an
    experiment folder from its ``raw.json`` (nothing is rendered, played back or measured again)."""
    path = Path(out) / RAW_FILE
    reps = Path(out) / REPLICATES_DIR
    if not path.is_file() and reps.is_dir():
        records = [read_results(p / RAW_FILE) for p in sorted(reps.iterdir()) if (p / RAW_FILE).is_file()]
        if records:
            previous = Path(out) / RESULTS_FILE
            command = read_results(previous).get("command") if previous.is_file() else None
            return finish_replicated(out, records, command=command)
    if not path.is_file():
        raise LiveError(f"{path}: not found; not a finished live experiment folder")
    return finish(out, read_results(path))

