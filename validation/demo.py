"""``exposim demo``: the main job end to end on the embedded synthetic default.

1. Synthesise a short stereo walk through ``forest_winter`` (Mitsuba render -> synthetic
   BorealHDR camera with noise), with noiseless ground-truth captures of the left camera (the
   one step 2 checks) at a few target exposures at every shot instant.  The recording goes into the dataset cache
   (``<render cache>/datasets/demo-<key>``, :func:`demo_dataset`), keyed by everything that
   decides its bytes, so a second demo with the same configuration reads it instead of
   writing another full copy (62 of the 74 MB of a default demo folder).
2. Check the emulator against that exact ground truth (the paper's bracket selector,
   HigherNoSat, per target exposure).
3. Run all seven AE methods in closed loop on the recording (``emulator.playback``).
4. Reduced feature (SIFT uniformity, matches) and stereo-VO benchmarks on the run.
5. Write ``report.md`` (tables + figures) and ``results.json`` in a new output folder; it
   holds the run results only, and names the recording it used.
"""

from __future__ import annotations

import hashlib
import inspect
import time
from pathlib import Path

import numpy as np

from emulator.io.files import REPORT_FILE, RESULTS_FILE, first_free, read_results, write_results, write_text
from emulator.report.figures import plural
from emulator.report.html import write_report
from emulator.cells import format_number

__all__ = ["run_demo", "demo_config", "emulation_check", "new_output_dir", "demo_dataset", "demo_dataset_key"]

GT_EXPOSURES_MS = (0.5, 3.0, 6.0, 12.0, 24.0, 45.0)
#: The report's figures and their captions (the two not shown in the text appear under "Figures").
FIGURE_CAPTIONS = {
    "run/exposure.png": "Exposure each method chose, per bracket cycle",
    "features/fig4_features.png": "Features per method (paper Fig. 4): uniformity, matches between consecutive "
                                  "images, success against the match threshold",
    "vo/fig6_rpe.png": "Stereo VO per method (paper Fig. 6): relative pose error against the pair length",
}
#: Sub-folder of the render cache that holds the demo's synthetic recordings.
DATASETS_FOLDER = "datasets"
#: Bump when the meaning of the key changes.
_DATASET_KEY_VERSION = 1
#: Modules whose source decides the bytes of the recording besides the renders (the render
#: cache key already covers the scene code): the walk, the camera model and the writer.
_DATASET_MODULES = ("scenes.synthesize", "scenes.trajectory", "synth.camera", "synth.imaging", "synth.sensor",
                    "synth.presets", "synth.response_fit", "synth.sequence", "synth.dataset")


#: How the demo renders its blurred walk: one render per bracket sweep and camera, warped to
#: every shot's exposure window (a sixth of the renders of one per shot), margins rounded up to
#: 8 px (two image sizes, so Dr.Jit compiles its kernels twice, not once per render), and the
#: faster OIDN preset (16-spp albedo and normal).  ``$EXPOSIM_DENOISE``, when set, names the denoiser.
RENDERING = dict(render_per="cycle", margin_step_px=8, denoise="oidn-fast")


def demo_config(quick: bool = False) -> dict:
    """Size of the demo: the default takes about a minute on 2 cores, ``quick`` well under one."""
    if quick:
        return dict(scene="forest_winter", n_cycles=4, width=96, height=60, spp=4, vo_frames=4, vo_ratio=0.9,
                    **RENDERING)
    # 256x160 at 8 spp: the cheapest size at which SIFT survives the renders' own noise and
    # the stereo VO tracks every frame of forest_winter (measured in validation.ae_study;
    # 192x120 at 8 spp failed 58 of 77 VO steps).  The VO's ratio test is 0.9 for the same
    # reason; the feature benchmark keeps the paper's 0.8.
    return dict(scene="forest_winter", n_cycles=12, width=256, height=160, spp=8, vo_frames=12, vo_ratio=0.9,
                **RENDERING)


def new_output_dir(base: str | Path = "exposim-demo") -> Path:
    """The first of ``exposim-demo-1``, ``-2``, ... that does not exist (never overwrites)."""
    return first_free(base, 1)


def _synth_kwargs(cfg: dict) -> dict:
    """The :func:`scenes.synthesize.synthesize` arguments of the demo's recording."""
    import os

    from scenes.denoise import ENV_DENOISE, default_denoiser

    # the denoiser by name, so that it enters the recording's key (:func:`demo_dataset_key`)
    denoise = default_denoiser() if os.environ.get(ENV_DENOISE, "").strip() else cfg["denoise"]
    return dict(n_cycles=cfg["n_cycles"], width=cfg["width"], height=cfg["height"], spp=cfg["spp"],
                render_per=cfg["render_per"], margin_step_px=cfg["margin_step_px"], denoise=denoise,
                gt_exposures_ms=GT_EXPOSURES_MS, gt_captures="noiseless", gt_cameras=("left",), seed=0)


def demo_dataset_key(cfg: dict) -> str:
    """Key (16 hex) of the demo's recording: the scene, the synthesis arguments, the source of
    the modules that write it (:data:`_DATASET_MODULES`), exposim, Mitsuba and Dr.Jit versions."""
    import importlib

    import scenes
    from emulator import __version__
    from scenes.cache import canonical_json, library_versions

    scene = scenes.get_scene(cfg["scene"], seed=0)
    code = hashlib.sha256()
    for name in _DATASET_MODULES:
        code.update(name.encode())
        code.update(inspect.getsource(importlib.import_module(name)).encode())
    material = {"v": _DATASET_KEY_VERSION, "scene": scene.key_material(), "synthesize": _synth_kwargs(cfg),
                "code": code.hexdigest(), "exposim": __version__, "versions": library_versions()}
    return hashlib.sha256(canonical_json(material).encode()).hexdigest()[:16]


def demo_dataset(cfg: dict, cache_dir=None, progress=None) -> tuple[Path, bool]:
    """The demo's synthetic recording, from the dataset cache or synthesised into it.

    Parameters
    ----------
    cfg : dict
        :func:`demo_config`.
    cache_dir : path, optional
        The render cache (default ``$EXPOSIM_CACHE`` or ``~/.cache/exposim/renders``); the
        recording lives in ``cache_dir/datasets/demo-<key>`` (:func:`demo_dataset_key`).
    progress : callable, optional
        ``progress(done, total)`` while synthesising.

    Returns
    -------
    (Path, bool)
        The recording and whether it was reused.  A cached recording is reused only when
        every file its manifest lists is present and unchanged; otherwise it is written
        again (a file someone added to it is never deleted: that is refused, naming it).
    """
    import scenes
    from emulator.errors import ExposimError, OutputExistsError
    from scenes.cache import resolve_cache_dir
    from scenes.synthesize import synthesize
    from synth.dataset import foreign_files, missing_files

    root = resolve_cache_dir(cache_dir)
    if root is None:
        raise ExposimError("the demo keeps its recording in the render cache; cache_dir=False is not supported")
    path = root / DATASETS_FOLDER / f"demo-{demo_dataset_key(cfg)}"

    def intact() -> bool:
        return path.is_dir() and not missing_files(path) and not foreign_files(path)

    if intact():
        return path, True
    scene = scenes.get_scene(cfg["scene"], seed=0)
    try:
        synthesize(scene, path, **_synth_kwargs(cfg), overwrite=path.exists(), progress=progress)
    except OutputExistsError:
        if not intact():  # not another demo that finished the same recording meanwhile
            raise
        return path, True
    return path, False


def emulation_check(dataset: Path, selector: str = "higher-no-sat") -> dict:
    """Emulate every ground-truth capture of ``dataset`` from the selected bracket of its cycle.

    Ground truth sits at the instants of the shots; for each cycle and target exposure the
    selector picks a bracket of the cycle and the emulated image is compared with the
    noiseless capture at that bracket's instant (same pose), so only emulation error and
    the bracket's own sensor noise remain.  RMSE in % of the DN range, over valid pixels.
    """
    from emulator.io.borealhdr import exposure_folder_name, load_sequence, sequence_response
    from emulator.io.png import read_png16
    from emulator.core.emulate import emulate
    from emulator.core.select import saturated_fraction, select

    seq = load_sequence(dataset)
    response = sequence_response(seq)
    rng = seq.white_level - seq.black_level
    levels = dict(white_level=seq.white_level, black_level=seq.black_level)
    gt_root = Path(dataset) / "ground_truth" / "captures_noiseless" / "camera_left"
    rows = []
    for cycle in seq:
        frames = cycle.frames["left"]
        if not frames:
            continue
        images = {b: f.load() for b, f in frames.items()}
        fractions = {b: saturated_fraction(img, **levels) for b, img in images.items()}
        for target in GT_EXPOSURES_MS:
            b = select(selector, target, fractions, **levels)
            frame = frames[b]
            gt_path = gt_root / exposure_folder_name(target) / f"{frame.timestamp_ns}.png"
            if not gt_path.is_file():
                continue
            gt = read_png16(gt_path).astype(np.float64)
            emu, valid = emulate(images[b], b, target, response, return_mask=True)
            diff = (emu.astype(np.float64) - gt)[valid]
            rows.append(
                {
                    "cycle": cycle.index,
                    "target_ms": target,
                    "bracket_ms": b,
                    "rmse_percent": float(100 * np.sqrt(np.mean(diff**2)) / rng) if diff.size else None,
                    "valid_fraction": float(valid.mean()),
                }
            )
    per_target = {}
    for t in GT_EXPOSURES_MS:
        vals = [r["rmse_percent"] for r in rows if r["target_ms"] == t and r["rmse_percent"] is not None]
        if vals:
            per_target[f"{t:g}"] = {"median_rmse_percent": float(np.median(vals)), "n": len(vals)}
    all_vals = [r["rmse_percent"] for r in rows if r["rmse_percent"] is not None]
    return {
        "selector": selector,
        "rows": rows,
        "per_target": per_target,
        "median_rmse_percent": float(np.median(all_vals)) if all_vals else None,
        "max_rmse_percent": float(np.max(all_vals)) if all_vals else None,
    }


def run_demo(output=None, *, quick: bool = False, progress=None, cache_dir=None) -> dict:
    """Run the demo into ``output`` (default: a new ``exposim-demo-N``); nothing is printed.

    Parameters
    ----------
    output : path, optional
        A new or empty folder; an existing non-empty one is refused
        (:class:`~emulator.errors.OutputExistsError`).
    quick : bool
        The smallest configuration (:func:`demo_config`).
    progress : callable, optional
        ``progress(stage, done, total)``, called as each of the four stages advances
        (``stage`` is a short label such as ``"1/4 synthesise forest_winter"``).
    cache_dir : path, optional
        Render cache, which also holds the synthetic recording (:func:`demo_dataset`).

    Returns
    -------
    dict
        ``output`` (the folder), ``report`` (the markdown of ``report.md``), ``total_s``,
        ``dataset`` (the recording used) and ``dataset_reused`` (True when an earlier demo
        had synthesised it).
    """
    from emulator.errors import OutputExistsError
    from emulator.io.borealhdr import load_sequence
    from emulator.metrics.bench import bench_features, bench_vo
    from emulator.metrics.vo import VOParameters
    from emulator.orchestration.runner import run_to_folder

    def say(stage: str, done: int, total: int) -> None:
        if progress is not None:
            progress(stage, done, total)

    cfg = demo_config(quick)
    out = Path(output) if output is not None else new_output_dir()
    if out.exists() and any(out.iterdir()):
        raise OutputExistsError(f"{out}: exists and is not empty; choose another --output")
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    timings = {}

    # 1. synthetic recording (from the dataset cache when an earlier demo made it) ------
    stage = f"1/4 synthesise {cfg['scene']}"
    say(stage, 0, cfg["n_cycles"] * 6)
    t0 = time.perf_counter()
    dataset, reused = demo_dataset(cfg, cache_dir, progress=lambda done, total: say(stage, done, total))
    say(stage, cfg["n_cycles"] * 6, cfg["n_cycles"] * 6)
    timings["synthesise_s"] = time.perf_counter() - t0

    # 2. emulator against exact ground truth ----------------------------------------------
    say("2/4 emulation against ground truth", 0, 1)
    t0 = time.perf_counter()
    emu = emulation_check(dataset)
    timings["emulation_check_s"] = time.perf_counter() - t0
    say("2/4 emulation against ground truth", 1, 1)

    # 3. closed loop ---------------------------------------------------------------------
    seq = load_sequence(dataset)
    run_dir = out / "run"
    stage = "3/4 closed loop, 7 methods"
    say(stage, 0, len(seq))
    t0 = time.perf_counter()
    run_summary = run_to_folder(
        seq, "all", run_dir, save="png16", progress=lambda done, total: say(stage, done, total),
        command="exposim demo",
    )
    timings["closed_loop_s"] = time.perf_counter() - t0

    # 4. features and VO -------------------------------------------------------------------
    say("4/4 features and stereo VO", 0, 1)
    t0 = time.perf_counter()
    feats = bench_features(run_dir, out / "features", command="exposim demo")
    vo = bench_vo(run_dir, out / "vo", max_frames=cfg["vo_frames"], rpe_on_failure=True, command="exposim demo",
                  parameters=VOParameters(ratio=cfg["vo_ratio"]))
    timings["benchmarks_s"] = time.perf_counter() - t0
    say("4/4 features and stereo VO", 1, 1)
    timings["total_s"] = time.perf_counter() - t_start

    results = {
        "config": cfg,
        "dataset": str(dataset),
        "dataset_reused": reused,
        "emulation": {k: v for k, v in emu.items() if k != "rows"},
        "run": run_summary,
        "features": feats,
        "vo": vo,
        "timings": timings,
    }
    write_results(out / RESULTS_FILE, results)
    report = _report(out, cfg, emu, run_dir, feats, vo, timings, dataset, reused)
    write_report(out, report, figures=FIGURE_CAPTIONS, sheets=[_run_sheet(run_dir)])
    return {"output": out, "report": report, "total_s": timings["total_s"], "dataset": dataset,
            "dataset_reused": reused}


def _run_sheet(run_dir: Path) -> str:
    """The closed-loop run's contact sheet (each method's emulated frames over sampled cycles)."""
    from emulator.io.runfolder import read_run_json, read_tables
    from emulator.report.html import run_contact_sheet

    info = read_run_json(run_dir)
    return run_contact_sheet(run_dir, info["methods"], read_tables(run_dir, info["methods"]),
                             white_level=info.get("white_level"))


def _method_rows(feats: dict, vo: dict, run_summary_path: Path) -> list[str]:
    run_results = read_results(run_summary_path) if run_summary_path.is_file() else {}
    methods = run_results.get("methods", {})
    fm = feats.get("methods", {})
    vm = vo.get("methods", {})
    lines = [
        "| method | median exposure (ms) | mean saturated (%) | median uniformity (%) | median matches | VO failed frames | "
        f"relative pose error, translation, median over pose pairs {_rpe_pairs(vm)} apart (% of that distance) |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for name in methods or fm:
        m = methods.get(name, {})
        f = fm.get(name, {})
        v = vm.get(name, {})
        lines.append(
            f"| {name} | {format_number(m.get('median_exposure_ms'))} | {format_number(100 * m['mean_saturated_fraction'] if 'mean_saturated_fraction' in m else None)} "
            f"| {format_number(None if f.get('median_uniformity') is None else 100 * f['median_uniformity'])} "
            f"| {format_number(f.get('median_matches'))} "
            f"| {len(v.get('failures', []))} of {plural(v['n_frames'], 'frame') if 'n_frames' in v else '- frames'} "
            f"| {format_number(_rpe_median(v))} |"
        )
    return lines


def _longest(v: dict) -> dict | None:
    """The RPE ``deltas`` entry of the longest pair length that has pairs, or None."""
    rpe = v.get("rpe") or {}
    return next((e for e in reversed(rpe.get("deltas", [])) if e.get("n_pairs") and _trans(e)), None)


def _trans(entry: dict):
    """Translation statistics (%) of one RPE ``deltas`` entry (``trans_pct`` in older results)."""
    return entry.get("trans_percent") or entry.get("trans_pct")


def _rpe_pairs(vo_methods: dict) -> str:
    """The pair length of the table's RPE column ("1.20 m", or the range over methods): the
    longest reference path length between two poses that has pairs."""
    lengths = sorted({round(e["delta_m"], 2) for e in map(_longest, vo_methods.values()) if e})
    if not lengths:
        return "the longest distance"
    return f"{lengths[0]:.2f} m" if len(lengths) == 1 else f"{lengths[0]:.2f}-{lengths[-1]:.2f} m"


def _rpe_median(v: dict):
    """Median translation RPE (%) at the longest pair length that has pairs, or None."""
    entry = _longest(v)
    return None if entry is None else _trans(entry).get("median")


def _rendering_note(dataset: Path) -> str:
    """One sentence on how the recording was rendered, read from its description."""
    from emulator.io.borealhdr import read_recording_metadata

    source = read_recording_metadata(Path(dataset)).get("source") or {}
    render, walk = source.get("render") or {}, (source.get("trajectory") or {}).get("walk")
    den = render.get("denoise") or {}
    settings = den.get("settings") or {}
    denoised = (f"denoised by Open Image Denoise ({settings.get('quality')} quality, albedo and normal at "
                f"{settings.get('aux_spp')} spp)" if den.get("name", "off") != "off" else "not denoised")
    blur = render.get("blur_shots")
    if not blur:
        return f"Rendering: {render.get('spp')} spp path tracing, {denoised}; no motion blur."
    per = "bracket sweep (6 shots)" if blur.get("render_per") == "cycle" else "shot"
    how = "turns like the BorealHDR backpack" if walk in (None, "borealhdr") else f"follows the {walk} walk"
    return (f"Rendering: {render.get('spp')} spp path tracing, {denoised}. The camera {how} and every shot "
            f"integrates the scene over its own exposure window (motion blur): one render per {per} and camera, "
            "with depth, warped to each window's sub-instants.")


def _report(out: Path, cfg: dict, emu: dict, run_dir: Path, feats: dict, vo: dict, timings: dict,
            dataset: Path, reused: bool) -> str:
    lines = [
        "# exposim demo",
        "",
        f"Scene `{cfg['scene']}`, {cfg['n_cycles']} bracket cycles (1..32 ms, 22 frames/s), "
        f"{cfg['width']}x{cfg['height']} px, {cfg['spp']} spp, synthetic BorealHDR camera (noise on), stereo; "
        f"SIFT ratio test {feats.get('parameters', {}).get('ratio')} for the features (the library's) and "
        f"{cfg['vo_ratio']} for VO (at this image size the stricter test leaves too few matches to track).",
        "",
        _rendering_note(dataset),
        "",
        f"Synthetic recording: `{dataset}` ("
        + ("reused: an earlier demo with the same configuration synthesised it" if reused else "synthesised now")
        + "; it lives in the render cache and is shared by every demo of this configuration).",
        "",
        "## Emulation against exact ground truth (the paper's bracket selector: higher bracket unless saturated)",
        "",
        "| target (ms) | median RMSE (% of range) | captures |",
        "| --- | --- | --- |",
    ]
    for t, v in emu["per_target"].items():
        lines.append(f"| {t} | {v['median_rmse_percent']:.3f} | {v['n']} |")
    lines += [
        "",
        f"Overall median {emu['median_rmse_percent']:.3f} %, max {emu['max_rmse_percent']:.3f} % "
        "(sensor noise of the source bracket included; paper: median 0.21 %, max 1.78 % after noise subtraction).",
        "",
        "## Seven AE methods in closed loop",
        "",
        *_method_rows(feats, vo, run_dir / "results.json"),
        "",
        f"![{FIGURE_CAPTIONS['run/exposure.png']}]({(run_dir / 'exposure.png').relative_to(out)})",
        "",
        "Feature and VO details: `features/report.md`, `vo/report.md`; run tables: `run/<method>/exposures.csv`.",
        "",
        "Timings: " + ", ".join(f"{k} {v:.1f}" for k, v in timings.items()),
        "",
    ]
    return "\n".join(lines)
