"""Run the experiment into a folder, and redraw its verdicts from the raw record.

:func:`run_live_experiment` (one seed) and :func:`run_replicated` (several) run every walk
as one task (:mod:`validation.live.walks`: record, emulated and live loops, comparisons,
run folders, benchmarks, noise variance ratio; serial, local Dask cluster or a scheduler
address), pool each seed's walks into its ``raw.json`` (:func:`assemble_raw`); :func:`finish`
turns that record into ``results.json``, ``report.md``
and the figures (:func:`redraw` does it again from ``raw.json`` alone), with the verdicts over the walks
from :mod:`validation.live.study_verdicts`.  All files go through :mod:`emulator.io`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from datetime import datetime, timezone
from functools import partial
from pathlib import Path

import numpy as np

from emulator.errors import OutputExistsError
from emulator.io.files import RESULTS_FILE, first_free, read_results, read_text, write_results
from emulator.io.runfolder import read_run_json, read_tables
from emulator.report.html import run_contact_sheet, write_report
import validation.ae_study as ae_study
from validation.live.compare import measure_noise_variance_ratio
from validation.live.config import BRIGHTENING_PAIRS, CONFIGS, LiveConfig, LiveError, config_from_dict
from validation.live.evidence import WALK_METRICS, WALKS_TABLE, parse_walks_table
from validation.live.loops import has_run_images
from validation.live.native import native_emulation_summary, native_markdown, native_rate_loop
from validation.live.portable import (check_plan_files, folder_check, folder_markdown, named_files, relative_command,
                                     study_command)
from validation.live.preregistration import (
    PREREG_FILE,
    STOP_FILE,
    preregistration,
    read_preregistration,
    read_stop,
    stop_record,
    write_preregistration,
)
from validation.live.report import evidence_markdown, plot_metrics, plot_trajectories, report_markdown
from validation.live.study_verdicts import POWER_FILE, evidence, judge_study, store_power, table_refusals
from validation.live.table_check import canonical_order, check_walks_table, record_walks
from validation.live.verdicts import assemble, ratio_use
from validation.live.walks import NATIVE_RUN, read_walk, run_walks

__all__ = ["RAW_FILE", "REPLICATES_DIR", "STUDY_FILE", "POWER_FILE", "NATIVE_RUN", "numbered_output",
           "run_live_experiment", "run_study", "assemble_raw", "finish", "evidence", "store_power", "run_replicated",
           "finish_replicated", "stop_study", "redraw"]

#: What :func:`redraw` recomputes the verdicts from (per-cycle comparisons, benchmark summaries).
RAW_FILE = "raw.json"
#: Sub-folder of :func:`run_replicated`'s experiments, one per seed.
REPLICATES_DIR = "replicates"
#: What a study folder was started with (configuration, replicates): ``--resume`` checks it.
STUDY_FILE = "study.json"


def numbered_output(out) -> Path:
    """``out`` if it does not exist or is empty, else the first free ``out-2``, ``out-3`` ... (never overwrite)."""
    out = Path(out)
    if not out.exists() or (out.is_dir() and not any(out.iterdir())):
        return out
    return first_free(out)


def _check_output(out: Path, resume: bool, study: dict) -> None:
    """Refuse a non-empty ``out`` (unless ``resume`` and it holds a study of the same configuration)."""
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        if not resume:
            raise OutputExistsError(f"{out}: exists and is not empty; refusing to overwrite (choose another folder, "
                                    "or --resume to finish the study in it)")
        path = out / STUDY_FILE
        if not path.is_file():
            raise LiveError(f"{path}: not found; {out} is not a live study folder to resume")
        before = read_results(path)
        if before != study:
            diff = sorted(k for k in set(before["config"]) | set(study["config"])
                          if before["config"].get(k) != study["config"].get(k))
            if before.get("replicates") != study.get("replicates"):
                diff.append("replicates")
            raise LiveError(f"{out}: holds a study of another configuration (differs in {', '.join(diff)}); "
                            "resume it with the same options")
        return
    out.mkdir(parents=True, exist_ok=True)
    write_results(out / STUDY_FILE, study, overwrite=False)


def _default_native(cfg: LiveConfig, native_loop):
    if native_loop is None and cfg.native:
        return partial(native_rate_loop, latency_frames=cfg.latency_frames, frame_rate_hz=cfg.frame_rate_hz)
    return native_loop


def _pooled_features(walks: list[dict], run: str) -> dict:
    """``bench_features``' results over the walks' runs ``run`` (each walk benchmarked on its own)."""
    from emulator.metrics.bench import pool_feature_runs

    entries = [w["benchmarks"]["features"][run] for w in walks]
    taus = walks[0]["benchmarks"]["feature_taus"]
    methods, rates = pool_feature_runs(entries, taus)
    return {"methods": methods, "success_curve": {"taus": taus, "rate": rates}, "runs": entries}


def assemble_raw(experiment, cfg: LiveConfig, failed: dict[str, str], command: str | None = None) -> dict:
    """``raw.json`` of one experiment (one seed) from its walk records; ``failed``: scene -> error of the walks
    without one.  The walks' figures are pooled as one experiment over its scenes always was."""
    from emulator import __version__

    walks = [read_walk(experiment, s) for s in cfg.scenes if s not in failed]
    present = [w["scene"] for w in walks]
    timings = {k: v for w in walks for k, v in w["timings"].items()}
    timings["total_s"] = float(sum(w["timings"][f"walk_{w['scene']}_s"] for w in walks))
    raw = {"config": cfg.to_dict(), "command": relative_command(command, experiment), "exposim_version": __version__,
           "render_variant": walks[0]["render_variant"] if walks else None, "timings": timings,
           "per_scene": {w["scene"]: {"comparison": w["comparison"], "trajectories": w["trajectories"],
                                      **({"native_emulation": w["native_emulation"]} if w.get("native_emulation")
                                         else {})} for w in walks},
           "summaries": {}, "findings": {},
           "noise_variance_ratio": walks[0]["noise_variance_ratio"] if walks else None,
           "noise_variance_ratio_brightening": walks[0]["noise_variance_ratio_brightening"] if walks else None,
           "failed_walks": [{"walk": f"{s}/seed{cfg.seed}", "error": e} for s, e in failed.items()],
           **({"method_processes": walks[0]["method_processes"]} if walks and "method_processes" in walks[0] else {})}
    if cfg.metrics and walks:
        study_cfg = ae_study.StudyConfig(scenes=tuple(present), n_cycles=cfg.n_cycles, width=cfg.width,
                                         height=cfg.height, spp=cfg.spp, vo_ratio=cfg.vo_ratio,
                                         segment_pairs=cfg.segment_pairs, taus=tuple(cfg.taus))
        for r in walks[0]["runs"]:
            vo = {w["scene"]: w["benchmarks"]["vo"][r] for w in walks}
            runs = {w["scene"]: w["run_summaries"][r] for w in walks}
            raw["summaries"][r] = ae_study.summarise(study_cfg, _pooled_features(walks, r), vo, runs)
            raw["findings"][r] = ae_study.evaluate_findings(raw["summaries"][r], cfg.taus)
    return raw


def run_study(experiments: list[tuple[Path, LiveConfig]], *, command: str | None = None, cache_dir=None,
              log: Callable[[str], None] | None = None, scheduler=None, n_workers: int | None = None,
              native_loop: Callable | None = None, progress: bool = True,
              keep_run_images: bool = True) -> list[dict]:
    """Every walk of ``experiments`` (folder, configuration) as one batch of tasks
    (:func:`validation.live.walks.run_walks`), then each experiment's ``raw.json`` and
    verdicts (:func:`finish`).  An experiment whose ``raw.json`` exists without failed walks
    is read, not run again.  Returns the experiments' raw records (one whose walks all failed
    has an empty ``per_scene`` and its ``failed_walks``).  ``keep_run_images`` False: each walk deletes its runs'
    images once its benchmarks have read them (:func:`validation.live.walks.run_walk`)."""
    done, todo = {}, []
    for exp, cfg in experiments:
        path = exp / RAW_FILE
        if path.is_file() and not read_results(path).get("failed_walks"):
            done[exp] = read_results(path)
        else:
            todo.append((exp, cfg))
    failed = run_walks(todo, scheduler=scheduler, n_workers=n_workers, cache_dir=cache_dir,
                       native_loop=_default_native(todo[0][1], native_loop) if todo else None, command=command,
                       progress=progress, log=log, keep_run_images=keep_run_images)
    for exp, cfg in todo:
        raw = assemble_raw(exp, cfg, {s: e for (x, s), e in failed.items() if x == Path(exp)}, command)
        write_results(exp / RAW_FILE, raw)
        if raw["per_scene"]:
            finish(exp, raw)
        done[exp] = raw
    return [done[exp] for exp, _ in experiments]


def run_live_experiment(out, config: LiveConfig | None = None, *, progress: bool = True, command: str | None = None,
                        cache_dir=None, log: Callable[[str], None] | None = None,
                        scheduler=None, native_loop: Callable | None = None, resume: bool = False,
                        n_workers: int | None = None, keep_run_images: bool = True) -> dict:
    """Run the experiment (one seed, a walk per scene) into ``out`` (a new or empty folder; see
    :func:`numbered_output`; ``resume``: finish the study already in ``out``, walks with a record
    are not run again).

    ``config`` defaults to ``CONFIGS["full"]``.  Each walk is one task
    (:func:`validation.live.walks.run_walk`): ``scheduler`` None or ``"serial"`` runs them in
    this process, ``"local"`` on a local Dask cluster (``n_workers``), ``"tcp://HOST:PORT"``
    on a running scheduler's workers; the same bytes on every path.  ``keep_run_images`` False: each
    walk deletes its runs' images once measured (the results are the same).  A walk that fails is
    listed in ``failed_walks`` (results.json) and the others are judged; if every walk fails,
    :class:`LiveError`.  Returns the content of ``results.json``.

    ``native_loop``: the native-rate live condition (issue 22), a callable
    ``native_loop(sequence, radiance, camera, methods, *, seed, noise, initial_ms, selector,
    response)`` yielding :class:`emulator.playback.CycleStep` per cycle with images kept (a
    camera at the recorder's frame rate with an exposure latency, the same closed loop as
    ``exposim run``); its run is ``live-native``.  Default (None):
    :func:`validation.live.native.native_rate_loop` at ``config.frame_rate_hz`` with
    ``config.latency_frames``, when ``config.native`` (else that condition is reported as
    not run in results.json ``conditions`` and ``comparisons``).
    """
    cfg = CONFIGS["full"] if config is None else config
    out = Path(out)
    _check_output(out, resume, {"config": cfg.to_dict(), "replicates": 1})
    records = run_study([(out, cfg)], command=command, cache_dir=cache_dir, log=log, scheduler=scheduler,
                        n_workers=n_workers, native_loop=native_loop, progress=progress,
                        keep_run_images=keep_run_images)
    raw = records[0]
    if not raw["per_scene"]:
        raise LiveError("every walk failed: " + "; ".join(f"{f['walk']}: {f['error']}" for f in raw["failed_walks"]))
    return read_results(out / RESULTS_FILE)


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


def _lead(results: dict) -> dict:
    """results.json's keys with what the study is and its headline first."""
    first = [k for k in ("experiment", "command", "n_walks", "headlines") if k in results]
    return {**{k: results[k] for k in first}, **{k: v for k, v in results.items() if k not in first}}


def _add_native(results: dict, records: list[dict], cfg: LiveConfig) -> None:
    """results.json's ``native_emulation`` over every walk of ``records`` (one experiment's raw record, or the
    replicates'), in place; nothing where no walk ran the emulated native-rate condition."""
    native = native_emulation_summary({f"{s}/seed{r['config']['seed']}": sc.get("native_emulation")
                                       for r in records for s, sc in (r.get("per_scene") or {}).items()},
                                      list(cfg.methods), seed=cfg.seed)
    if native is not None:
        results["native_emulation"] = native


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
    scenes = list(per_scene)  # the walks that ran (a failed walk is listed in failed_walks)
    nvr_up = raw.get("noise_variance_ratio_brightening")
    if nvr_up is None:  # a record from before this measurement: measure it on a chart with the run's camera
        nvr_up = _brightening_on_chart(out / "datasets" / scenes[0], cfg)
    results = assemble(cfg, per_scene, raw["summaries"], raw["findings"], raw["noise_variance_ratio"],
                       list(cfg.methods))
    results.update(evidence(cfg, [raw], folder=out))
    results["noise_variance_ratio_brightening"] = {"plain": nvr_up["plain"], "consistent": nvr_up["consistent"]}
    results["noise_variance_ratio_brightening_detail"] = nvr_up
    results["emulation_ratio_use"] = ratio_use(per_scene, list(cfg.methods))
    _add_native(results, [raw], cfg)
    results.update({
        "experiment": "live versus emulated",
        "exposim_version": raw.get("exposim_version"),
        "command": relative_command(raw.get("command"), out),
        "config": cfg.to_dict(),
        "render_variant": raw.get("render_variant"),
        "timings": raw.get("timings", {}),
        "failed_walks": raw.get("failed_walks", []), **{k: raw[k] for k in ("method_processes",) if k in raw},
        "files": {"report": "report.md", "metrics_figure": "metrics.png" if cfg.metrics else None,
                  "exposure_figures": {s: f"exposure_{s}.png" for s in scenes}, "raw": RAW_FILE,
                  "walks": "walks/<scene>.json", "runs": "runs/<scene>/<run>",
                  "features": "features/<scene>/<run>", "vo": "vo/<scene>/<run>"},
    })
    for s in scenes:
        plot_trajectories(per_scene[s]["trajectories"], out / f"exposure_{s}.png", title=s)
    if cfg.metrics:
        plot_metrics(results, out / "metrics.png")
    results["study_folder"] = folder_check(out)
    write_report(out, report_markdown(results) + native_markdown(results), sheets=[_live_sheets(out, scenes[0])])
    results = _lead(results)
    write_results(out / RESULTS_FILE, results)
    return results


def run_replicated(out, config: LiveConfig | None = None, replicates: int = 1, *, command: str | None = None,
                   resume: bool = False, calibration_studies: int | None = None, **kwargs) -> dict:
    """The experiment on ``replicates`` seeds (``config.seed``, ``+1``, ...), each scene of each one an
    independent walk; the verdicts over all of them.

    Each replicate is a complete experiment in ``out/replicates/seed<S>`` (its own
    results.json over its scenes); ``out/results.json`` and ``out/report.md`` hold the
    verdicts over every walk (:func:`finish_replicated`).  Every walk of every replicate is
    one task of one batch (:func:`run_study`); ``kwargs`` (scheduler, n_workers, cache_dir,
    log, progress, native_loop, keep_run_images) go there.  ``resume``: finish the study already in ``out``.
    """
    cfg = CONFIGS["full"] if config is None else config
    if replicates < 1:
        raise LiveError(f"replicates must be >= 1, got {replicates}")
    out = Path(out)
    _check_output(out, resume, {"config": cfg.to_dict(), "replicates": int(replicates)})
    stop = read_stop(out) if resume else None
    if stop is not None:
        raise LiveError(f"{out / STOP_FILE}: the study was stopped {stop['stopped']} ({stop['reason']}) and judged at "
                        f"{stop['n_walks']} walks; a stopped study is not resumed (--redraw recomputes its verdicts)")
    if not resume or read_preregistration(out) is not None:  # before the first walk; a resume may not change it
        write_preregistration(out, preregistration(cfg, replicates))
    t0 = time.perf_counter()
    experiments = [(out / REPLICATES_DIR / f"seed{cfg.seed + k}", replace(cfg, seed=cfg.seed + k))
                   for k in range(replicates)]
    records = run_study(experiments, command=command, **kwargs)
    if not any(r["per_scene"] for r in records):
        raise LiveError("every walk failed; see the failed_walks of " + ", ".join(
            str(e / RAW_FILE) for e, _ in experiments))
    return finish_replicated(out, records, command=command, wall_s=time.perf_counter() - t0,
                             calibration_studies=calibration_studies)


def finish_replicated(out, records: list[dict], command: str | None = None, power_seeds: int = 100,
                      wall_s: float | None = None, calibration_studies: int | None = None) -> dict:
    """``results.json`` and ``report.md`` of the verdicts over the replicates' walks (``power_seeds``:
    simulated studies per point of the power functions)."""
    out = Path(out)
    failed = [f for r in records for f in r.get("failed_walks", [])]
    records = [r for r in records if r.get("per_scene", True)]  # a replicate whose every walk failed: failed only
    if not records:
        raise LiveError(f"{out}: no walk of the study ran (" + "; ".join(f"{f['walk']}: {f['error']}" for f in failed)
                        + ")")
    cfg = config_from_dict(records[0]["config"])
    stop = read_stop(out)
    if stop is not None and sorted(int(r["config"]["seed"]) for r in records) != sorted(int(s) for s in stop["seeds"]):
        raise LiveError(f"{out / STOP_FILE}: the study was stopped with seeds {list(stop['seeds'])} judged; the "
                        f"records given are of seeds {[r['config']['seed'] for r in records]}")
    command = relative_command(command, out)
    results = {"experiment": "live versus emulated, replicated", "command": command,
               "config": cfg.to_dict(), "replicates": [f"{REPLICATES_DIR}/seed{r['config']['seed']}" for r in records],
               "timings": {"total_s": float(sum((r.get("timings") or {}).get("total_s", 0.0) for r in records)),
                           **({} if wall_s is None else {"wall_s": float(wall_s)})},
               "failed_walks": failed, **{k: records[0][k] for k in ("method_processes",) if k in records[0]}}
    results.update(evidence(cfg, records, power_seeds=power_seeds, folder=out, calibration_studies=calibration_studies))
    _add_native(results, records, cfg)
    results["study_folder"] = folder_check(out, named_files(results))
    write_report(out, "# Live versus emulated, replicated\n\n"
                 + f"{len(records)} replicate(s) of the experiment (seeds "
                 + ", ".join(str(r["config"]["seed"]) for r in records) + f"), {results['n_walks']} walks. "
                 + f"Command (paths relative to this folder): `{command}`\n\n"
                 + folder_markdown(results["study_folder"])
                 + "".join(f"Failed walk (not judged; `--resume` runs it again): {f['walk']}: {f['error']}\n\n"
                           for f in results["failed_walks"]) + evidence_markdown(results) + native_markdown(results))
    results = _lead(results)
    write_results(out / RESULTS_FILE, results)
    return results


def _live_sheets(out: Path, scene: str) -> str:
    """Contact sheets of the first scene: what each method saw in every run (emulated and live); runs whose
    images were deleted (``--no-run-images``) are left out."""
    parts = []
    folder = Path(out) / "runs" / scene
    for run_dir in sorted(p for p in folder.glob("*") if (p / "run.json").is_file() and has_run_images(p)):
        info = read_run_json(run_dir)
        sheet = run_contact_sheet(run_dir, info["methods"], read_tables(run_dir, info["methods"]),
                                  white_level=info.get("white_level"))
        parts.append(sheet.replace("What each method saw", f"{scene}, {run_dir.name}: what each method saw", 1))
    return "\n".join(parts)


def verdicts_from_table(out, power_seeds: int = 100, calibration_studies: int | None = None) -> dict:
    """The verdicts of a study folder that keeps only its per-walk table (and its results.json for the
    configuration): results.json's evidence and report.md recomputed from ``walks.csv``, read strictly against the
    study's record and put in the walks' key order first (:mod:`validation.live.table_check`): the same rows in
    any order give the same bytes."""
    out = Path(out)
    prev = read_results(out / RESULTS_FILE) if (out / RESULTS_FILE).is_file() else {}
    if "config" not in prev:
        raise LiveError(f"{out / RESULTS_FILE}: needed beside {WALKS_TABLE} for the study's configuration")
    cfg = config_from_dict(prev["config"])
    text, name = read_text(out / WALKS_TABLE, LiveError), str(out / WALKS_TABLE)
    check_walks_table(text, name, metrics=WALK_METRICS, methods=cfg.methods, walks=record_walks(prev))
    walks, methods, tables = canonical_order(*parse_walks_table(text, name), scenes=cfg.scenes,
                                             method_order=cfg.methods)
    results = {k: prev[k] for k in ("experiment", "command", "config", "replicates", "timings", "failed_walks",
                                    "native_emulation", "method_processes") if k in prev}  # not in the table
    results.update({"walks": walks, "n_walks": len(walks), "walks_table": WALKS_TABLE})
    results["command"] = relative_command(results.get("command"), out)
    results.update(judge_study(cfg, tables, methods, walks, out, power_seeds, calibration_studies))
    results["study_folder"] = folder_check(out, named_files(results))
    write_report(out, f"# Live versus emulated, recomputed from {WALKS_TABLE}\n\n{len(walks)} walks. Command "
                 f"(paths relative to this folder): `{results.get('command')}`\n\n"
                 + folder_markdown(results["study_folder"]) + evidence_markdown(results) + native_markdown(results))
    results = _lead(results)
    write_results(out / RESULTS_FILE, results)
    return results


def _stopped_records(out: Path, stop: dict, cfg: LiveConfig, command: str | None) -> list[tuple[Path, dict, bool]]:
    """(seed folder, raw record, whether to write it) of each seed a stop record judges: its ``raw.json`` where it
    holds every scene without a failed walk, else assembled from the seed's walk records (nothing is written)."""
    out_records = []
    for seed in stop["seeds"]:
        exp = out / REPLICATES_DIR / f"seed{int(seed)}"
        if (exp / RAW_FILE).is_file():
            raw = read_results(exp / RAW_FILE)
            if not raw.get("failed_walks") and sorted(raw.get("per_scene") or {}) == sorted(cfg.scenes):
                out_records.append((exp, raw, False))
                continue
        out_records.append((exp, assemble_raw(exp, replace(cfg, seed=int(seed)), {}, command), True))
    return out_records


def _write_stopped(records: list[tuple[Path, dict, bool]]) -> list[dict]:
    """Write the seeds' raw.json that :func:`_stopped_records` assembled, and the results of each seed without
    them (:func:`finish` writes results.json last: one cut short is finished again); returns the raw records."""
    out = []
    for exp, raw, new in records:
        if new:
            write_results(exp / RAW_FILE, raw)
            raw = read_results(exp / RAW_FILE)  # as a later --redraw reads it
        if new or not (exp / RESULTS_FILE).is_file():
            finish(exp, read_results(exp / RAW_FILE))  # finish turns the record's lists into arrays in place
        out.append(raw)
    return out


def stop_study(out, reason: str, *, command: str | None = None, calibration_studies: int | None = None,
               when: str | None = None) -> dict:
    """Stop the pre-registered study in ``out`` before its planned walks, for ``reason`` (a rule that does not
    read the data, such as its budget), and draw its verdicts, its final look.

    The stop record (:func:`validation.live.preregistration.stop_record`: the seeds whose every walk is finished)
    and each of those seeds' raw record (its ``raw.json`` where whole, else assembled from its walk records,
    :func:`assemble_raw`) are made in memory and checked first (a ``walks.csv`` the judged walks would not keep is
    refused); then ``stop.json`` (with ``command``, the stop's own command line) is written, then the seeds'
    ``raw.json`` and results (:func:`finish`), then the study's results.json and report.md over their walks
    (:func:`finish_replicated`), which record the command that ran the walks
    (:func:`~validation.live.portable.study_command`).  A failure after ``stop.json`` is mended by ``--redraw``,
    which assembles a judged seed's missing ``raw.json`` the same way, finishes a seed without results and draws
    the look with the command and the count of calibration studies the stop used (``stop.json`` keeps it).
    ``when``: the stop's time (UTC, ISO 8601; default now).  Refused (:class:`LiveError`), with nothing written,
    for a folder without a study, a plan, a complete seed, every planned seed complete, or a stop record already."""
    out = Path(out)
    if not (out / STUDY_FILE).is_file():
        raise LiveError(f"{out / STUDY_FILE}: not found; {out} is not a live study folder")
    before = read_stop(out)
    if before is not None:
        raise LiveError(f"{out / STOP_FILE}: the study was already stopped {before['stopped']} ({before['reason']}); "
                        "--redraw recomputes its verdicts")
    when = when or datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    record = stop_record(out, reason, when=when)
    if command is not None:
        record["command"] = relative_command(command, out)
    record["calibration_studies"] = calibration_studies  # the look's count, for a --redraw that mends it
    cfg = config_from_dict(read_results(out / STUDY_FILE)["config"])
    walks_command = study_command(out / REPLICATES_DIR, record["seeds"], cfg.scenes)
    records = _stopped_records(out, record, cfg, walks_command)
    refusals = table_refusals(out, cfg, [raw for _, raw, _ in records])
    if refusals:
        raise LiveError("; ".join(refusals) + " (an earlier look's table, with walks the stop leaves out: nothing was"
                        " written and the study is not stopped; move the table away and stop again)")
    write_results(out / STOP_FILE, record, overwrite=False)
    return finish_replicated(out, _write_stopped(records), command=walks_command,
                             calibration_studies=calibration_studies)


def redraw(out, calibration_studies: int | None = None) -> dict:
    """Recompute the verdicts and rewrite ``results.json``, ``report.md``, ``calibration.json`` and the figures
    of an experiment folder from its ``raw.json`` (nothing is rendered, played back or measured again).
    ``calibration_studies``: plasmode studies of the calibration; None: as many as a stopped study's stop used,
    else as many as the folder's results.json used (the default where it has none)."""
    previous = Path(out) / RESULTS_FILE
    path = Path(out) / RAW_FILE
    reps = Path(out) / REPLICATES_DIR
    prev = read_results(previous) if previous.is_file() else {}
    check_plan_files(Path(out), prev)
    stop = read_stop(out)
    if calibration_studies is None:
        calibration_studies = (stop["calibration_studies"] if stop is not None and "calibration_studies" in stop
                               else (prev.get("calibration") or {}).get("n_studies"))
    if not path.is_file() and reps.is_dir() and stop is not None and (Path(out) / STUDY_FILE).is_file():
        # a stopped study: the seeds its record names, a missing raw.json assembled as the stop assembles it
        cfg = config_from_dict(read_results(Path(out) / STUDY_FILE)["config"])
        command = study_command(Path(out) / REPLICATES_DIR, stop["seeds"], cfg.scenes)
        records = _write_stopped(_stopped_records(Path(out), stop, cfg, command))
        return finish_replicated(out, records, command=command, calibration_studies=calibration_studies)
    if not path.is_file() and reps.is_dir():
        judged = None if stop is None else {f"seed{int(s)}" for s in stop["seeds"]}  # a stop binds the redraw
        records = [read_results(p / RAW_FILE) for p in sorted(reps.iterdir())
                   if (p / RAW_FILE).is_file() and (judged is None or p.name in judged)]
        if records:
            return finish_replicated(out, records, command=prev.get("command"), calibration_studies=calibration_studies)
    if not path.is_file() and (Path(out) / WALKS_TABLE).is_file():
        return verdicts_from_table(out, calibration_studies=calibration_studies)  # the walks table alone
    if not path.is_file():
        raise LiveError(f"{path}: not found; not a finished live experiment folder")
    raw = read_results(path)
    if "per_scene" in raw and not raw["per_scene"]:
        raise LiveError(f"{path}: every walk failed; nothing to judge (--resume runs them again)")
    return finish(out, raw)

