"""One walk of the live study as one task (issue 22): record, loops, comparisons, benchmarks.

The unit of the study is an independent walk (a scene with its trajectory, render and
capture-noise seeds).  :func:`run_walk` does everything one walk needs, in its own folders
of the experiment (``datasets/<scene>``, ``runs/<scene>/<run>``, ``features/<scene>/<run>``,
``vo/<scene>/<run>``), and writes what the verdicts need as ``walks/<scene>.json``
(:func:`walk_record_path`): the per-cycle comparisons, the trajectories, the closed-loop
summaries, the feature benchmark's per-run entries, the VO benchmarks and the noise
variance ratios.  It is a pure function of its arguments (every draw seeded from the
configuration), so :func:`run_walks` can run the walks serially, on a local Dask cluster
or on a scheduler's workers (:func:`emulator.orchestration.distributed.run_tasks`, one error policy: a
walk that raises becomes an error row, the others go on) and the records are the same
bytes on every path.  A walk whose record exists is not run again (resume).
"""

from __future__ import annotations

import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from emulator.io.files import read_results, to_jsonable, write_results
from validation.live import loops, native
from validation.live.compare import exposure_log2_errors, image_errors, measure_noise_variance_ratio
from validation.live.config import (
    BRIGHTENING_PAIRS,
    CONTROL,
    NOISE_OPTIONS,
    RESEEDED,
    VARIANTS,
    LiveConfig,
    config_from_dict,
)
from validation.live.seeds import loop_items, loop_names
from validation.live.walk_memory import live_window_ms, renderers_kept, shared_radiance

__all__ = ["WALKS_DIR", "NATIVE_RUN", "CONTROL_STREAM", "RESEEDED_STREAMS", "control_seed", "walk_record_path",
           "walk_name", "run_walk", "run_walks", "read_walk"]

#: Sub-folder of an experiment with one record per finished walk.
WALKS_DIR = "walks"
#: Run name of the native-rate live condition.
NATIVE_RUN = "live-native"
#: The folders of one walk inside its experiment (cleared before a walk is run again).
WALK_FOLDERS = ("datasets", "runs", "features", "vo")


def walk_record_path(experiment, scene: str) -> Path:
    """``<experiment>/walks/<scene>.json``: the record of a finished walk."""
    return Path(experiment) / WALKS_DIR / f"{scene}.json"


def walk_name(scene: str, seed: int) -> str:
    """The walk's name in results.json (``<scene>/seed<seed>``)."""
    return f"{scene}/seed{int(seed)}"


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


#: Purpose word of the re-seeded live control's capture-noise stream.
CONTROL_STREAM = 22_033
#: Purpose word of each re-seeded live run's capture-noise stream (:data:`~validation.live.config.RESEEDED`).
RESEEDED_STREAMS = {RESEEDED["live-same-instant"]: CONTROL_STREAM, RESEEDED["live-fixed-instant"]: 22_034,
                    RESEEDED["live-native"]: 22_035}


def control_seed(seed: int, scene: str, stream: int = CONTROL_STREAM) -> int:
    """The capture-noise seed of a re-seeded live run of walk (``scene``, ``seed``): a stream of its own
    (from ``[seed, stream, CRC-32 of the scene]``; ``stream``: :data:`RESEEDED_STREAMS`, the same-instant
    control's by default), never another walk's or replicate's seed (studies before it used ``seed + 1``,
    the next replicate's live seed)."""
    from scenes.trajectory import stream_key

    return int(np.random.SeedSequence(stream_key(seed, stream, scene)).generate_state(1)[0])


def _loop_items(cfg: LiveConfig, mode: str) -> Callable[[], list]:
    """What each loop of the walk is given to run, fresh per call: the methods, and each stochastic method's
    seeds 1 .. k - 1 as instances of their own (:func:`validation.live.seeds.loop_items`)."""
    return lambda: loop_items(cfg.methods, cfg.stochastic_seeds, mode)


def _n_loop_methods(cfg: LiveConfig) -> int:
    return len(loop_names(cfg.methods, cfg.stochastic_seeds))


def method_processes() -> dict:
    """How the walk's loops ran the methods, for its record: every method in every condition (live and emulated)
    in its own worker process forked from one fork server, with NumPy's kernels there
    (:mod:`emulator.numpy_dispatch`)."""
    from emulator import numpy_dispatch

    return {"workers": "process", "numpy": numpy_dispatch.describe()}


def _collect(iterator, n: int, desc: str, progress: bool) -> list:
    got = []
    with _bar(n, desc, progress) as bar:
        for cs in iterator:
            got.append(cs)
            bar.update(1)
    return got


def _loops(cfg: LiveConfig, seq, radiance, camera, model, response, native_loop, tag: str, progress: bool,
           timings: dict, scene: str, native_out: dict | None = None) -> dict:
    """Every run of the walk: {run name: [CycleStep with images]}; ``native_out`` gets the native
    emulation's per-frame errors (:func:`validation.live.native.native_image_errors`).

    The cycle-rate live runs advance together, and the native-rate live run with its re-seeded twin, so
    that the radiance of a shot several of them capture is integrated once
    (:class:`~validation.live.loops.SharedRadiance`); each run is what it is alone."""
    native_out = {} if native_out is None else native_out
    from emulator.playback import RunConfig

    common = dict(config=RunConfig(initial_ms=cfg.initial_ms, selector=cfg.selector), response=response)
    names = _loop_items(cfg, common["config"].mode)
    cycles: dict = {}
    t0 = time.perf_counter()
    for opt, mode in NOISE_OPTIONS.items():
        cycles[f"emulated-{opt}"] = _collect(
            loops.iter_emulated(seq, names(), noise=mode, noise_model=model, seed=cfg.seed, **common),
            len(seq.cycles), f"{tag}: emulated loop ({opt})", progress)
    timings[f"emulated_{scene}_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    live_runs = [(v, v, cfg.seed) for v in VARIANTS]
    if cfg.control:  # each cycle-rate live run again, with capture-noise streams of its own
        live_runs += [(RESEEDED[f"live-{v}"].removeprefix("live-"), v,
                       control_seed(cfg.seed, scene, RESEEDED_STREAMS[RESEEDED[f"live-{v}"]])) for v in VARIANTS]
    shared = shared_radiance(radiance, cfg, _n_loop_methods(cfg), len(live_runs))
    with _bar(len(seq.cycles) * len(live_runs), f"{tag}: live loops ({len(live_runs)} runs)", progress) as bar:
        got = loops.lockstep([loops.iter_live(seq, shared, camera, names(), timing=timing, noise=cfg.capture_noise,
                                              seed=seed, **common) for _, timing, seed in live_runs],
                             on_step=lambda: bar.update(1))
    for (label, _, _), steps in zip(live_runs, got):
        cycles[f"live-{label}"] = steps
    if native_loop is not None:
        _native_loops(cfg, seq, radiance, camera, names, native_loop, response, cycles, native_out, timings, scene,
                      tag, progress, t0)
        return cycles
    timings[f"live_{scene}_s"] = time.perf_counter() - t0
    return cycles


def _native_loops(cfg: LiveConfig, seq, radiance, camera, names: Callable, native_loop, response, cycles: dict,
                  native_out: dict, timings: dict, scene: str, tag: str, progress: bool, t0: float) -> None:
    """The native-rate live run (every frame) and, with the control, its re-seeded twin advanced with it (only
    the frames the benchmarks use kept); then the emulated native-rate condition (:func:`_emulated_native`)."""
    from emulator.playback import RunConfig

    kw = dict(noise=cfg.capture_noise, initial_ms=cfg.initial_ms, selector=cfg.selector, response=response,
              every_frame=True)
    seeds = [cfg.seed] + ([control_seed(cfg.seed, scene, RESEEDED_STREAMS[RESEEDED[NATIVE_RUN]])]
                          if cfg.control else [])
    shared = shared_radiance(radiance, cfg, _n_loop_methods(cfg), len(seeds))
    runs = [native_loop(seq, shared, camera, names(), seed=s, **kw) for s in seeds]
    if cfg.control:  # the re-seeded frames are streamed: only the benchmarked ones are kept
        config = RunConfig(initial_ms=cfg.initial_ms, selector=cfg.selector, rate="native",
                           latency_frames=cfg.latency_frames, native_warp="rotation")
        runs[1] = _thinned(runs[1], set(native.cycle_picks(native.native_provider(seq, response, config))))
    with _bar(len(seq.cycles) * 6 * len(runs), f"{tag}: live loop (native rate, {len(runs)} runs)",
              progress) as bar:
        got = loops.lockstep(runs, on_step=lambda: bar.update(1))
    timings[f"live_{scene}_s"] = time.perf_counter() - t0
    _emulated_native(cfg, seq, response, got[0], cycles, native_out, timings, scene,
                     (lambda: got[1]) if cfg.control else None, names)


def _thinned(frames, keep: set):
    """Every frame of ``frames``, those whose index is not in ``keep`` without their steps (their images):
    what :func:`validation.live.native.per_cycle` reads of them (the failures) is left."""
    from dataclasses import replace

    for cs in frames:
        yield cs if cs.cycle in keep else replace(cs, steps={})


def _emulated_native(cfg: LiveConfig, seq, response, every: list, cycles: dict, native_out: dict, timings: dict,
                     scene: str, reseeded: Callable | None = None, items: Callable | None = None) -> None:
    """The emulated native-rate condition beside the native live one: both runs benchmarked on
    the frame at each cycle's first shot; and the open-loop image error of native emulation (with and
    without the warp) at the exposures the native live camera applied.  ``reseeded``: the re-seeded
    native-rate live loop (every frame), benchmarked on the same frames."""
    from emulator.playback import RunConfig

    names = list(cfg.methods)
    t0 = time.perf_counter()
    config = RunConfig(initial_ms=cfg.initial_ms, selector=cfg.selector, rate="native",
                       latency_frames=cfg.latency_frames, native_warp="rotation")
    provider, emulated = native.emulated_native_loop(seq, names if items is None else items(), response, config)
    picks = native.cycle_picks(provider)
    cycles[NATIVE_RUN] = native.per_cycle(every, picks)
    cycles[native.EMULATED_NATIVE_RUN] = native.per_cycle(emulated, picks)
    timings[f"emulated_native_{scene}_s"] = time.perf_counter() - t0
    if reseeded is not None:  # its frames were streamed with the live runs (their time is in live_<scene>_s)
        cycles[RESEEDED[NATIVE_RUN]] = native.per_cycle(reseeded(), picks)  # only the picked frames are kept
    t0 = time.perf_counter()
    native_out.update(native.native_image_errors(seq, every, response, config, names))
    for m, err in exposure_log2_errors(emulated, every, names).items():
        native_out[m]["exposure_log2_error"] = err.tolist()  # every frame after the first
    timings[f"native_image_errors_{scene}_s"] = time.perf_counter() - t0


def _comparisons(cfg: LiveConfig, cycles: dict, seq, response) -> dict:
    names = list(cfg.methods)
    comp: dict = {}
    for opt in NOISE_OPTIONS:
        for v in VARIANTS + ((CONTROL,) if cfg.control else ()):
            emu, lv = cycles[f"emulated-{opt}"], cycles[f"live-{v}"]
            err = exposure_log2_errors(emu, lv, names)
            img = image_errors(emu, lv, names, seq, response)
            comp[f"{opt}/{v}"] = {m: {"exposure_log2_error": err[m], **img[m]} for m in names}
    if cfg.control:
        err = exposure_log2_errors(cycles["live-same-instant"], cycles[f"live-{CONTROL}"], names)
        comp["live/control"] = {m: {"exposure_log2_error": err[m]} for m in names}
    return comp


def _benchmarks(cfg: LiveConfig, exp: Path, scene: str, runs: list[str], progress: bool, command, timings) -> dict:
    """The feature bench's per-run entry and the VO bench of each run of this walk."""
    from emulator.metrics.bench import bench_features, bench_vo
    from emulator.metrics.features import DEFAULT_TAUS
    from emulator.metrics.vo import VOParameters

    taus = sorted(set(int(t) for t in DEFAULT_TAUS) | set(int(t) for t in cfg.taus))
    params = VOParameters(ratio=cfg.vo_ratio, seed=cfg.seed)
    features, vo = {}, {}
    t0 = time.perf_counter()
    for r in runs:
        run_dir = exp / "runs" / scene / r
        feats = bench_features([run_dir], exp / "features" / scene / r, taus=taus, seed=cfg.seed, progress=progress,
                               command=command)
        features[r] = feats["runs"][0]
        vo[r] = bench_vo(run_dir, exp / "vo" / scene / r, parameters=params, rpe_on_failure=True, progress=progress,
                         command=command)
    timings[f"metrics_{scene}_s"] = time.perf_counter() - t0
    return {"features": features, "vo": vo, "feature_taus": taus}


def _recording(ds: Path) -> tuple:
    """(sequence, response, camera, noise model) of the walk's recording ``ds``: the noise model is synth's
    camera's (:func:`synth.noise_model.noise_model_of`) through the recording's response."""
    from emulator.io.borealhdr import load_sequence, sequence_response
    from emulator.noise import NoiseModel
    from synth.noise_model import noise_model_of
    from synth.sequence import load_camera

    seq = load_sequence(ds)
    response = sequence_response(seq)
    camera = load_camera(ds)
    synth_model = noise_model_of(camera)
    model = NoiseModel(response, synth_model.gain_e_per_h, synth_model.read_noise_e, synth_model.name)
    return seq, response, camera, model


def _trajectories(cycles: dict, methods) -> dict:
    """{run: {method: timestamps, targets and brackets per cycle}} of the walk's runs (results.json's
    trajectories)."""
    return {r: {m: {"timestamp_ns": [cs.steps[m].timestamp_ns for cs in steps if m in cs.steps],
                    "target_ms": [cs.steps[m].target_ms for cs in steps if m in cs.steps],
                    "bracket_ms": [cs.steps[m].bracket_ms for cs in steps if m in cs.steps]}
                for m in methods} for r, steps in cycles.items()}


def _noise_ratios(ratio_input: tuple, cfg: LiveConfig, scene_name: str, timings: dict) -> tuple[dict, dict]:
    """The noise variance ratios of the walk's first left radiance (:func:`measure_noise_variance_ratio`): the
    usual pairs and the brightening ones."""
    t0 = time.perf_counter()
    nvr = measure_noise_variance_ratio(*ratio_input, repeats=cfg.noise_repeats, seed=cfg.seed)
    nvr_up = measure_noise_variance_ratio(*ratio_input, repeats=cfg.noise_repeats, seed=cfg.seed,
                                          pairs=BRIGHTENING_PAIRS)
    nvr["input"] = nvr_up["input"] = f"first left radiance of {scene_name}"
    timings[f"noise_ratio_{scene_name}_s"] = time.perf_counter() - t0
    return nvr, nvr_up


def run_walk(config: dict, scene_name: str, experiment: str, cache_dir=None, native_loop: Callable | None = None,
             command: str | None = None, progress: bool = False, log: Callable[[str], None] | None = None,
             keep_run_images: bool = True) -> dict:
    """Run one walk (``scene_name`` at ``config``'s seed) into ``experiment``; write and return its record.

    ``config``: :meth:`LiveConfig.to_dict` (plain data, so the call can travel to a Dask
    worker).  Folders of an earlier, unfinished attempt at this walk are removed first.
    ``keep_run_images`` False: the runs' images are written fast (PNG level 0) and deleted once the
    benchmarks have read them (the record is the same).
    Returns ``{"walk", "seconds"}``; the record itself is ``walks/<scene>.json``.
    """
    import scenes
    from scenes.synthesize import synthesize
    from scenes.walkshots import walk_radiance

    cfg = config_from_dict(config)
    exp = Path(experiment)
    say = log or (lambda msg: None)
    for folder in WALK_FOLDERS:
        shutil.rmtree(exp / folder / scene_name, ignore_errors=True)
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    tag = walk_name(scene_name, cfg.seed)
    scene = scenes.get_scene(scene_name, seed=cfg.seed, **cfg.scene_parameters(scene_name))
    scene = scene.with_emitter_weights(dict(cfg.emitter_weights))
    ds = exp / "datasets" / scene_name
    with _bar(cfg.n_cycles * 6, f"{tag}: render + record", progress) as bar:
        synthesize(scene, ds, n_cycles=cfg.n_cycles, width=cfg.width, height=cfg.height, spp=cfg.spp, stereo=True,
                   seed=cfg.seed, render_seed=cfg.seed, noise=cfg.capture_noise,
                   save_radiance=cfg.keep_radiance or scene.is_static,  # a walk's live shots integrate the renders
                   render_per=cfg.render_per, denoise=cfg.denoise, max_window_ms=live_window_ms(),
                   adaptive=cfg.adaptive,
                   cache_dir=cache_dir,
                   progress=lambda d, n: bar.update(d - bar.n))
    timings[f"record_{scene_name}_s"] = time.perf_counter() - t_start
    say(f"{tag}: recorded {cfg.n_cycles} cycles in {timings[f'record_{scene_name}_s']:.0f} s")
    seq, response, camera, model = _recording(ds)
    first_ms = seq.cycles[0].available(("left",))[0]
    first = seq.cycles[0].frames["left"][first_ms].timestamp_ns
    # live shots blurred over their windows; the renders (and depths) of the walk are kept for all its live runs
    radiance = walk_radiance(ds, scene, cache_dir=cache_dir, keep=renderers_kept(cfg)) or loops.DatasetRadiance(ds)
    # the first left shot's radiance, as the recording captured it (the radiance files are written only for a
    # still scene, whose shots are not integrated, or when they are kept)
    ratio_input = (radiance(first, "left", first_ms) if getattr(radiance, "exposure_aware", False)
                   else radiance(first, "left"), camera, response, model)
    native_errors: dict = {}
    cycles = _loops(cfg, seq, radiance, camera, model, response, native_loop, tag, progress, timings, scene_name,
                    native_errors)
    runs = list(cycles)
    comp = _comparisons(cfg, cycles, seq, response)
    names = loop_names(cfg.methods, cfg.stochastic_seeds)  # every seed of a stochastic method is benchmarked
    summaries = {}
    try:  # the run images go with --no-run-images whether the walk ends here or fails on its way
        for r in runs:
            loops.write_run_folder(exp / "runs" / scene_name / r, ds, cycles[r], names,
                                   white_level=seq.white_level, black_level=seq.black_level,
                                   description={"run": r, "scene": scene_name}, png_level=1 if keep_run_images else 0)
            summaries[r] = _runs_summary(cycles[r], names)
        trajectories = _trajectories(cycles, cfg.methods)
        del cycles
        nvr, nvr_up = _noise_ratios(ratio_input, cfg, scene_name, timings)
        if not cfg.keep_radiance:
            shutil.rmtree(ds / "ground_truth" / "radiance", ignore_errors=True)
        bench = _benchmarks(cfg, exp, scene_name, runs, progress, command, timings) if cfg.metrics else None
    finally:
        if not keep_run_images:  # the benchmarks have read them (or the walk failed: nothing will)
            for r in runs:
                loops.drop_run_images(exp / "runs" / scene_name / r)
    timings[f"walk_{scene_name}_s"] = time.perf_counter() - t_start
    record = {"walk": tag, "scene": scene_name, "config": cfg.to_dict(), "runs": runs,
              "render_variant": scenes.choose_variant(), "comparison": comp, "trajectories": trajectories,
              "run_summaries": summaries, "benchmarks": bench, "noise_variance_ratio": nvr,
              "noise_variance_ratio_brightening": nvr_up, "timings": timings, "method_processes": method_processes(),
              **({"native_emulation": native_errors} if native_errors else {})}
    write_results(walk_record_path(exp, scene_name), to_jsonable(record))
    say(f"{tag}: done in {timings[f'walk_{scene_name}_s'] / 60:.1f} min")
    return {"walk": tag, "seconds": timings[f"walk_{scene_name}_s"]}


def run_walks(experiments: list[tuple[Path, LiveConfig]], *, scheduler=None, n_workers: int | None = None,
              cache_dir=None, native_loop: Callable | None = None, command: str | None = None,
              progress: bool = True, log: Callable[[str], None] | None = None, keep_run_images: bool = True) -> dict:
    """Run every walk of ``experiments`` whose record does not exist yet, as one batch of tasks.

    ``scheduler``: None or ``"serial"`` (this process, one walk after the other), ``"local"``
    (a local Dask cluster, ``n_workers`` processes), a ``tcp://``/``tls://`` address or a
    :class:`distributed.Client` (:func:`emulator.orchestration.distributed.open_client`); on Dask the
    workers must see ``experiments`` and ``cache_dir`` under the same paths.  ``keep_run_images``: as
    :func:`run_walk`.  Returns
    ``{(experiment, scene): error text}`` of the walks that failed (empty when all ran).
    """
    from emulator.orchestration.distributed import open_client, run_tasks

    todo = [(exp, cfg, s) for exp, cfg in experiments for s in cfg.scenes
            if not walk_record_path(exp, s).is_file()]
    if not todo:
        return {}
    serial = scheduler in (None, "serial")
    args = [(cfg.to_dict(), s, str(exp), None if cache_dir is None else str(cache_dir), native_loop, command,
             progress and serial, log if serial else None, keep_run_images) for exp, cfg, s in todo]
    keys = [walk_name(s, cfg.seed) for _, cfg, s in todo]
    with _bar(len(todo), "walks", progress and not serial) as bar:
        def tick(done: int, total: int) -> None:
            bar.update(done - bar.n)

        if serial:
            outcomes = run_tasks(run_walk, args, keys=keys, progress=tick)
        else:
            with open_client(scheduler, n_workers=n_workers, retries=1) as client:
                outcomes = run_tasks(run_walk, args, client=client, retries=1, keys=keys, progress=tick)
    failed = {}
    for (exp, _, s), o in zip(todo, outcomes):
        if o.error is not None:
            failed[(Path(exp), s)] = o.error
            if log is not None:
                log(f"{o.key}: FAILED ({o.error})")
    return failed


def read_walk(experiment, scene: str) -> dict:
    """The record :func:`run_walk` wrote."""
    return read_results(walk_record_path(experiment, scene))
