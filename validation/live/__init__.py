"""Live versus emulated closed loop: does the offline benchmark judge AE methods as a live camera would?

Run::

    exposim validate live -o OUT [--quick] [--scenes a,b] [--cycles N] [--size WxH] [--seed S]
    python -m validation.live -o OUT ...          (the same)

For every scene (default ``forest_winter``, ``sun_glare``, ``forest_edge``, ``forest_summer``):

1. **Recording**: a stereo bracketed walk (:func:`scenes.synthesize.synthesize`, 1..32 ms
   sweeps at 22 frames/s, the BorealHDR-fitted camera with noise), with every shot's
   radiance kept as OpenEXR (``save_radiance``): the radiance the camera saw at that instant.
2. **Emulated loops**: the normal closed loop (:func:`emulator.playback.iter_run`) of the
   seven AE methods on the recording, with emulation noise ``"none"`` (exact eq. 2, *plain*)
   and ``"consistent"`` (the noise of a capture at the target, from synth's camera through
   :func:`synth.noise_model.noise_model_of`).
3. **Live loops** (:func:`~validation.live.loops.iter_live`): every cycle the camera
   captures at the method's own exposure from the radiance at that instant
   (:func:`synth.capture`, with noise, seeded), and the method reads that capture.  Two timing variants:

   * ``same-instant``: the capture happens at the timestamp of the bracket the emulator
     would use for the live loop's target (the selector run on the recorded brackets), so
     the pose is the one the emulated image comes from: isolates the photometric error;
   * ``fixed-instant``: the capture happens at one fixed instant per cycle, the cycle's
     **first shot** (the 1 ms bracket's timestamp, so no extra render), whatever bracket
     the emulator would use: adds the motion between brackets that real data has (up to
     5 shots, 227 ms).

   A control, ``same-instant-reseeded``, repeats the same-instant live loop with other
   capture-noise seeds: how far two live runs of the same walk disagree.

   The native-rate live loop (:func:`~validation.live.native.native_rate_loop`, run
   ``live-native``): the camera runs its AE on every frame at the recorder's 22 fps with an
   exposure latency (default 1 frame), shots timestamped at mid-exposure; the frame at each
   cycle's first shot is benchmarked.
4. **Comparison** per method, noise option and timing variant: exposure trajectories
   (|log2(emulated_ms / live_ms)| per cycle, cycle 0 excluded since both start at
   ``initial_ms``), left images (RMSE in % of the DN range over the emulation's valid
   pixels, and the valid fraction), then the benchmark metrics of each run
   (:func:`emulator.metrics.bench.bench_features`, :func:`~emulator.metrics.bench.bench_vo`,
   summarised as :func:`validation.ae_study.summarise` does) and the ranking of the methods
   per metric, live vs emulated (Kendall tau-b, :func:`scipy.stats.kendalltau`); the
   paper's findings (:func:`validation.ae_study.evaluate_findings`) evaluated on either side.
5. **Noise variance ratio**: emulated over live capture noise variance, measured from
   repeated captures of one rendered frame, per intensity bin, for plain and consistent
   emulation (:func:`~validation.live.compare.measure_noise_variance_ratio`, binned by
   :func:`emulator.noise.noise_variance_ratio`).

Writes ``OUT/results.json``, ``OUT/report.md``, ``OUT/exposure_<scene>.png`` (trajectories),
``OUT/metrics.png`` (metric bars), and the runs, datasets and benchmark folders beside
them.  An existing ``OUT`` that is not empty is never overwritten: the next free
``OUT-2``, ``OUT-3`` ... is used and named in the output.

Modules: :mod:`~validation.live.config` (the configuration), :mod:`~validation.live.loops`
(live and emulated loops, run folders), :mod:`~validation.live.compare` (per-cycle
comparisons, Kendall tau, noise variance ratio), :mod:`~validation.live.verdicts` (the
numbers of results.json, flip causes), :mod:`~validation.live.report` (figures, report.md;
the verdicts' sections in :mod:`~validation.live.evidence_report`),
:mod:`~validation.live.walks` (one walk as one task: serial, local Dask cluster or a scheduler
address; resume; its memory budget in :mod:`~validation.live.walk_memory`),
:mod:`~validation.live.experiment` (the study, each seed's ``raw.json``, :func:`redraw`; the
verdicts over the walks in :mod:`~validation.live.study_verdicts`), :mod:`~validation.live.cli`.
"""

import importlib

#: Public name -> the module that defines it (imported on first use: ``exposim`` registers
#: ``validate live`` through :mod:`validation.live.cli` without loading the experiment).
_HOMES = {
    **dict.fromkeys(("exposure_log2_errors", "image_errors", "kendall_tau", "measure_noise_variance_ratio"),
                    "validation.live.compare"),
    **dict.fromkeys(("CONFIGS", "CONTROL", "METHODS", "METRICS", "NOISE_OPTIONS", "SCENES", "VARIANTS", "LiveConfig",
                     "LiveError"), "validation.live.config"),
    **dict.fromkeys(("finish", "numbered_output", "redraw", "run_live_experiment"), "validation.live.experiment"),
    **dict.fromkeys(("DatasetRadiance", "iter_emulated", "iter_live", "write_run_folder"), "validation.live.loops"),
    "native_rate_loop": "validation.live.native",
    "main": "validation.live.cli",  # python -m validation.live
    **dict.fromkeys(("run_walk", "run_walks"), "validation.live.walks"),
}

__all__ = [
    "LiveConfig",
    "CONFIGS",
    "SCENES",
    "METHODS",
    "VARIANTS",
    "CONTROL",
    "NOISE_OPTIONS",
    "METRICS",
    "LiveError",
    "DatasetRadiance",
    "iter_live",
    "iter_emulated",
    "native_rate_loop",
    "write_run_folder",
    "exposure_log2_errors",
    "image_errors",
    "kendall_tau",
    "measure_noise_variance_ratio",
    "run_live_experiment",
    "finish",
    "redraw",
    "numbered_output",
    "run_walk",
    "run_walks",
    "main",
]


def __getattr__(name: str):
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'validation.live' has no attribute {name!r}")
    return getattr(importlib.import_module(home), name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOMES))
