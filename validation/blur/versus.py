"""Each AE method's features and VO metrics, live against emulated, with exposure-time blur and without.

Issue 21's last item of ``exposim validate blur``.  The machinery is the live study's
(:mod:`validation.live.loops`: the one closed loop of :mod:`emulator.playback` over a
:class:`~emulator.playback.LiveCycleProvider` or an
:class:`~emulator.playback.EmulatedProvider`; :func:`~validation.live.loops.write_run_folder`;
the benchmarks of :mod:`emulator.metrics`; :func:`validation.ae_study.summarise`).

Per walk (a scene with the realistic ``borealhdr`` walk and its own seed; walks are the units):

1. two recordings of the same walk, from the same renders (``render_per="cycle"``: one render
   per sweep and camera): ``blurred`` (every shot integrated over its exposure window) and
   ``sharp`` (every shot at its trigger instant, warped from the same renders: no blur, the
   same render noise, so the difference between the two is the blur alone);
2. on each: the live loop (the method's own exposure captured at the instant of the bracket
   the emulator would use, ``same-instant`` timing, integrated over its own window on the
   blurred recording), the emulated loop with plain emulation and with ``--blur consistent``
   (:class:`emulator.playback.motion.BlurHook` fed the recording's own ``imu/imu.csv``, windows
   starting at the trigger: the synthetic convention);
3. the features (median matches, median uniformity) and the VO (failed frames, translation
   RPE through evo) of every run.

Differences are emulated minus live, per method and metric: over walks (bootstrap, with at
least two walks) and, for the per-frame features, over frames (paired circular block
bootstrap, pooled over walks, with at least :data:`MIN_FRAMES` pairs).  A difference whose 95 %
interval lies inside the metric's equivalence margin
(:data:`validation.live.config.EQUIVALENCE_MARGINS`) ``agrees``; one whose interval lies
wholly beyond it ``disagrees``; anything else is ``undetermined``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import validation.ae_study as ae_study
from validation.live.config import EQUIVALENCE_MARGINS
from validation.live.loops import iter_emulated, iter_live, write_run_folder

__all__ = ["SCENE_BLUR", "RUNS", "METRICS", "record_walk", "walk_runs", "bench_walk", "compare", "run_versus"]

#: The two recordings of one walk: name -> exposure-time integration.
SCENE_BLUR = {"blurred": True, "sharp": False}
#: Runs on each recording: live (same-instant), emulated plain and blur-consistent.
RUNS = ("live", "emulated-plain", "emulated-consistent")
#: Fewest frame pairs an interval over frames decides on (fewer: ``undetermined``).
MIN_FRAMES = 10
#: Compared metrics: name -> (per-walk key path in ``ae_study.summarise(...)["per_scene"][scene][method]``,
#: per-frame list in the features results or None).
METRICS = {
    "median_matches": (("median_matches",), "matches"),
    "median_uniformity": (("median_uniformity",), "uniformity"),
    "vo_failed_frames": (("vo", "n_failed_frames"), None),
    "rpe_trans_pct": (("vo", "rpe_trans_pct"), None),
}


def record_walk(scene, folder: Path, cfg, seed: int, integrate: bool) -> Path:
    """One stereo recording of the walk of ``seed`` (one render per sweep; ``integrate``: blur)."""
    from scenes.synthesize import synthesize

    return synthesize(scene, folder, n_cycles=cfg.versus_cycles, width=cfg.width, height=cfg.height,
                      spp=cfg.versus_spp, stereo=True, seed=seed, render_seed=seed, noise=True, walk=cfg.walk,
                      blur=True, render_per="cycle", integrate=integrate, denoise=cfg.sharpness_denoise,
                      cache_dir=cfg.cache_dir)


def _consistent_hook(seq, response):
    """``--blur consistent`` on a synthetic recording: its own gyro, trigger-start windows, no bias removal."""
    from emulator.playback.motion import BlurHook, recording_motion

    return BlurHook(recording_motion(seq, stamp="start", remove_bias=False), response, False)


def walk_runs(scene, ds: Path, cfg, seed: int) -> dict:
    """``{run: [CycleStep]}`` of the three runs of :data:`RUNS` on one recording (images kept)."""
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.playback import RunConfig
    from scenes.walkshots import walk_radiance
    from synth.sequence import load_camera

    seq = load_sequence(ds)
    response = sequence_response(seq)
    config = RunConfig(initial_ms=cfg.versus_initial_ms)
    names = list(cfg.versus_methods)
    radiance = walk_radiance(ds, scene, cache_dir=cfg.cache_dir)
    live = list(iter_live(seq, radiance, load_camera(ds), names, timing="same-instant", noise=True, seed=seed,
                          config=config, response=response))
    plain = list(iter_emulated(seq, names, noise="none", seed=seed, config=config, response=response))
    from emulator.playback import iter_run

    cons = list(iter_run(seq, names, config, response=response, emulate_right=True, keep_images=True,
                         blur=_consistent_hook(seq, response)))
    return {"live": live, "emulated-plain": plain, "emulated-consistent": cons}


def bench_walk(out: Path, scene_name: str, ds: Path, runs: dict, cfg, seed: int) -> dict:
    """Run folders, features and VO of each run; ``{run: {"summary": {method: entry}, "frames": {...}}}``."""
    from emulator.io.borealhdr import load_sequence
    from emulator.metrics.bench import bench_features, bench_vo
    from emulator.metrics.vo import VOParameters

    seq = load_sequence(ds)
    names = list(cfg.versus_methods)
    study_cfg = ae_study.StudyConfig(scenes=(scene_name,), n_cycles=cfg.versus_cycles, width=cfg.width,
                                     height=cfg.height, spp=cfg.versus_spp, vo_ratio=cfg.versus_vo_ratio)
    out_runs = {}
    for r, cycles in runs.items():
        folder = write_run_folder_for(out / "runs" / r, ds, cycles, names, seq)
        feats = bench_features([folder], out / "features" / r, seed=seed)
        vo = bench_vo(folder, out / "vo" / r, parameters=VOParameters(ratio=cfg.versus_vo_ratio, seed=seed),
                      rpe_on_failure=True)
        per = ae_study.summarise(study_cfg, feats, {scene_name: vo}, {})["per_scene"][scene_name]
        frames = {key: {m: list(feats["runs"][0]["methods"][m][key]) for m in names
                        if m in feats["runs"][0]["methods"]}
                  for key in {v[1] for v in METRICS.values() if v[1]}}
        out_runs[r] = {"summary": {m: _entry(per.get(m)) for m in names}, "frames": frames,
                       "median_exposure_ms": {m: _median_or_none([cs.steps[m].target_ms for cs in cycles
                                                                  if m in cs.steps]) for m in names}}
    return out_runs


def _median_or_none(values) -> float | None:
    return float(np.median(values)) if len(values) else None


def write_run_folder_for(folder: Path, ds: Path, cycles, names, seq) -> Path:
    return write_run_folder(folder, ds, cycles, names, white_level=seq.white_level, black_level=seq.black_level)


def _entry(e: dict | None) -> dict:
    """The compared metrics of one method's summary entry (None where not measured)."""
    out = {}
    for metric, (path, _) in METRICS.items():
        v = e
        for k in path:
            v = v.get(k) if isinstance(v, dict) else None
        out[metric] = None if v is None or not np.isfinite(float(v)) else float(v)
    return out


def _verdict(ci, margin: float) -> str:
    if ci is None:
        return "undetermined"
    lo, hi = ci
    if -margin <= lo and hi <= margin:
        return "agrees"
    if lo > margin or hi < -margin:
        return "disagrees"
    return "undetermined"


def compare(walks: list[dict], methods, *, seed: int = 0) -> dict:
    """Emulated minus live per scene blur, emulated run, method and metric, with intervals and verdicts.

    ``walks``: one record per walk, ``{"walk": name, "by_blur": {blur: bench_walk(...)}}``.
    """
    from emulator.core.stats import difference_interval

    table: dict = {}
    for blur in SCENE_BLUR:
        for run in RUNS[1:]:
            rows = {}
            for m in methods:
                row = {}
                for metric, (_, frame_key) in METRICS.items():
                    got = [w["by_blur"][blur] for w in walks if blur in w["by_blur"]]
                    live = [g["live"]["summary"][m][metric] for g in got]
                    emu = [g[run]["summary"][m][metric] for g in got]
                    to_nan = lambda xs: np.array([np.nan if x is None else x for x in xs], dtype=float)  # noqa: E731
                    per_walk = difference_interval(to_nan(emu), to_nan(live), seed=seed)
                    cell = {"live": live, "emulated": emu, "per_walk": per_walk, "per_frame": None}
                    if frame_key is not None:
                        a, b = _aligned_frames(got, run, m, frame_key)
                        cell["per_frame"] = difference_interval(a, b, "median", block=True, seed=seed)
                    frames_ok = cell["per_frame"] is not None and cell["per_frame"]["n"] >= MIN_FRAMES
                    primary = per_walk if per_walk["n"] >= 2 else cell["per_frame"] if frames_ok else None
                    margin = EQUIVALENCE_MARGINS[metric]
                    cell.update(margin=margin, basis=("walks" if primary is per_walk else
                                                      "frames" if primary is not None else None),
                                verdict=_verdict(primary["ci95"] if primary else None, margin))
                    row[metric] = cell
                rows[m] = row
            table[f"{blur}/{run}"] = rows
    return table


def _aligned_frames(got: list[dict], run: str, method: str, key: str) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame values of ``key`` of ``run`` and of live, pooled over walks, frame by frame."""
    a, b = [], []
    for g in got:
        x, y = g[run]["frames"][key].get(method, []), g["live"]["frames"][key].get(method, [])
        n = min(len(x), len(y))
        a += list(x[:n])
        b += list(y[:n])
    return np.asarray(a, dtype=float), np.asarray(b, dtype=float)


def run_versus(out: Path, cfg, *, tick=None) -> dict:
    """Every walk of the table (``cfg.versus_walks`` seeds from ``cfg.seed``): records, runs, benchmarks, table."""
    import shutil

    import scenes
    from emulator.io.files import write_results

    tick = tick or (lambda n: None)
    walks = []
    for k in range(cfg.versus_walks):
        seed = cfg.seed + k
        scene = scenes.get_scene(cfg.scene, seed=seed)
        rec = {"walk": f"{cfg.scene}/seed{seed}", "by_blur": {}}
        for blur, integrate in SCENE_BLUR.items():
            base = Path(out) / "versus" / f"seed{seed}" / blur
            ds = record_walk(scene, base / "dataset", cfg, seed, integrate)
            runs = walk_runs(scene, ds, cfg, seed)
            rec["by_blur"][blur] = bench_walk(base, cfg.scene, ds, runs, cfg, seed)
            shutil.rmtree(base / "runs", ignore_errors=True)  # images: large, and the benchmarks have read them
            tick(1)
        walks.append(rec)
        write_results(Path(out) / "versus" / f"seed{seed}" / "walk.json", rec, float_digits=12)  # kept as it comes
    return {"walks": walks, "table": compare(walks, cfg.versus_methods, seed=cfg.seed),
            "settings": {"runs": list(RUNS), "scene_blur": list(SCENE_BLUR), "live_timing": "same-instant",
                         "recording": "render_per=cycle, one render per sweep and camera shared by both recordings",
                         "consistent": "emulator.playback.motion.BlurHook, the recording's imu.csv, stamp=start"}}
