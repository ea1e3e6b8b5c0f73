"""The feature and VO benchmarks over run folders: compute, then write results.

:func:`bench_features` and :func:`bench_vo` are what ``exposim bench features|vo`` call.
Each writes into its output folder ``results.json`` (every number, and the arrays
behind the figures), PNG figures drawn by :mod:`emulator.report.bench`, and
``report.md``.  The VO benchmark's code lives in :mod:`emulator.metrics.vo_bench` and the
shared helpers in :mod:`emulator.metrics.bench_common`; every name stays importable from
here.  They refuse an output folder that already holds ``results.json``
unless ``force`` is given, and check every input (run folders, calibration, image size,
reference overlap) before the long computation starts.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from emulator.errors import MetricsError
from emulator.io.files import RESULTS_FILE, prepare_output, write_results
from emulator.io.runfolder import RunFolder, read_run_folder
from emulator.metrics.bench_common import CONVERSION, features_sheet, method_frames, progress_iter, benchmark_frames
from emulator.version import __version__
from emulator.metrics.features import (
    DEFAULT_TAUS,
    GRID_CELLS,
    RATIO_TEST,
    analyse_sequence,
    load_gray8,
    success_curve,
)
from emulator.metrics.vo_bench import (  # re-exported: the VO benchmark lives in emulator.metrics.vo_bench
    DEFAULT_DELTA_FRACTIONS,
    FAILURE_POLICY,
    no_reference_note,
    REFERENCE_MAX_DIFF_S,
    REFINE_PAIRS,
    REFINE_THRESHOLD_FRACTION,
    SYNTHETIC_REFERENCE,
    bench_vo,
    evo_result_path,
)
from emulator.report import bench as report
from emulator.report.html import write_report
from emulator.core.settling import trending_methods
from emulator.io.runcsv import read_tables
from emulator.report.run import per_recorder_cycle

__all__ = [
    "bench_features",
    "bench_vo",
    "CONVERSION",
    "FAILURE_POLICY",
    "DEFAULT_DELTA_FRACTIONS",
    "REFERENCE_MAX_DIFF_S",
    "SYNTHETIC_REFERENCE",
    "REFINE_PAIRS",
    "REFINE_THRESHOLD_FRACTION",
    "no_reference_note",
    "evo_result_path",
    "pool_feature_runs",
]


def tau_grid(max_min_matches: int, *, n: int = 100) -> list[int]:
    """Thresholds of the success curve: the paper's 5..500 in steps of 5, extended past the
    largest per-run minimum of matches (where every curve is 0), in about ``n`` steps.

    >>> tau_grid(120)[:3], tau_grid(120)[-1], tau_grid(17762)[-1], len(tau_grid(17762))
    ([5, 10, 15], 500, 17820, 99)
    """
    top = max(int(DEFAULT_TAUS[-1]), int(max_min_matches) + 1)
    step = max(5, -(-top // n // 5) * 5)
    top = -(-top // step) * step
    return list(range(step, top + step, step))


def _still_trending(run_dir, names: list[str]) -> dict:
    """``{"still_trending": ...}`` of the run's methods whose exposure was still moving one way at its end
    (:mod:`emulator.core.settling`, per recorder cycle); empty where all settled or the tables cannot tell."""
    try:
        tables = read_tables(run_dir, names)
    except (OSError, ValueError, KeyError):  # a folder without usable tables: nothing to say
        return {}
    trending = trending_methods({n: per_recorder_cycle(t).get("target_ms", []) for n, t in tables.items()})
    return {"still_trending": trending} if trending else {}


def _run_features(run: RunFolder, max_frames: int | None, progress, **analysis) -> dict:
    """One run folder's entry of ``results["runs"]``: each method's :func:`analyse_sequence` (``analysis``:
    its keywords) on the left images, and whether the method was still trending."""
    per_method = {}
    for name, method in run.methods.items():
        frames = method_frames(method, max_frames)
        images = (
            (f.timestamp_ns, f.exposure_ms, load_gray8(f.left, white_level=run.white_level,
                                                       black_level=run.black_level))
            for f in progress_iter(frames, progress, f"features {name}", len(frames))
        )
        per_method[name] = analyse_sequence(images, **analysis).to_dict()
    return {
        "run_dir": str(run.path),
        "sequence": None if run.sequence is None else str(run.sequence),
        "white_level": run.white_level,
        "black_level": run.black_level,
        "methods": per_method,
        **_still_trending(run.path, list(per_method)),
    }


def bench_features(
    run_dirs: str | Path | Sequence[str | Path],
    out_dir: str | Path,
    *,
    methods: Sequence[str] | None = None,
    grid: tuple[int, int] = GRID_CELLS,
    ratio: float = RATIO_TEST,
    n_features: int = 0,
    matcher: str = "flann",
    scale: float = 1.0,
    max_frames: int | None = None,
    every_frame: bool = False,
    taus: Sequence[int] | None = None,
    seed: int = 0,
    force: bool = False,
    progress: bool = False,
    command: str | None = None,
) -> dict:
    """SIFT uniformity, consecutive matches and success rate of every method (Fig. 4).

    Parameters
    ----------
    run_dirs : path or sequence of paths
        Run folders of ``exposim run`` (one per sequence); the success rate of a method
        is the fraction of these runs it completes.
    out_dir : path
        Output folder: ``results.json``, ``fig4_features.png``, ``report.md``.
    methods : sequence of str, optional
        Restrict to these methods.
    grid, ratio, n_features, matcher, seed
        See :mod:`emulator.metrics.features`.
    scale : float
        Image scale before SIFT, (0, 1]; 1 = full resolution (the paper).
    max_frames : int, optional
        Use only the first ``max_frames`` images of each method (a reduced run).
    every_frame : bool
        A native-rate run (``exposim run --rate native``): every frame instead of one per
        recorder cycle (:func:`~emulator.metrics.bench_common.benchmark_frames`).
    taus : sequence of int, optional
        Thresholds of the success curve; default :func:`tau_grid`, the paper's 5..500
        extended until every method's curve reaches 0.
    force : bool
        Overwrite an existing ``results.json``.
    progress : bool
        Show tqdm progress bars (on stderr).
    command : str, optional
        The command line, recorded in the results.

    Returns
    -------
    dict
        The content of ``results.json``.
    """
    if isinstance(run_dirs, (str, Path)):
        run_dirs = [run_dirs]
    if not run_dirs:
        raise MetricsError("bench_features: no run folder given")
    out = prepare_output(out_dir, force=force)
    runs: list[RunFolder] = [benchmark_frames(read_run_folder(d, list(methods) if methods else None), every_frame)
                             for d in run_dirs]
    parameters = {
        "grid": [int(grid[0]), int(grid[1])],
        "ratio": ratio,
        "n_features": n_features,
        "matcher": matcher,
        "scale": scale,
        "max_frames": max_frames,
        **({"every_frame": True} if every_frame else {}),
        "seed": seed,
        "conversion": CONVERSION,
        "sift": "cv2.SIFT_create defaults: nOctaveLayers=3, contrastThreshold=0.04, edgeThreshold=10, sigma=1.6",
    }
    run_results = [_run_features(run, max_frames, progress, grid=grid, ratio=ratio, n_features=n_features,
                                 matcher=matcher, scale=scale, seed=seed) for run in runs]
    if taus is None:  # to where every curve has reached 0, so the success verdicts are not trivially true
        taus = tau_grid(max((r["methods"][m].get("min_matches") or 0 for r in run_results for m in r["methods"]),
                            default=0))
    taus = [int(t) for t in taus]
    summary, rates = pool_feature_runs(run_results, taus)
    results = {
        "benchmark": "features",
        "exposim_version": __version__,
        "command": command,
        "parameters": parameters,
        "n_runs": len(run_results),
        "methods": summary,
        "success_curve": {"taus": taus, "rate": rates},
        "runs": run_results,
        "figures": {"fig4": "fig4_features.png"},
        "report": "report.md",
    }
    report.plot_features(results, out / "fig4_features.png")
    sheet = features_sheet(runs[0], run_results[0], max_frames)
    write_report(out, report.features_report(results, "fig4_features.png"), figures=["fig4_features.png"],
                 sheets=[sheet])
    write_results(out / RESULTS_FILE, results)
    return results


def pool_feature_runs(run_results: Sequence[dict], taus: Sequence[int]) -> tuple[dict, dict]:
    """Per method, the figures pooled over runs, and the success curve at ``taus``.

    ``run_results``: the ``runs`` entries of :func:`bench_features` (one per run folder),
    possibly from several calls (the live study benchmarks each walk on its own and pools
    them here).  Returns ``(methods, rates)``: ``results["methods"]`` and
    ``results["success_curve"]["rate"]``.
    """
    names: list[str] = []
    for r in run_results:
        names += [m for m in r["methods"] if m not in names]
    taus = [int(t) for t in taus]
    summary, rates = {}, {}
    for name in names:
        seqs = [r["methods"][name] for r in run_results if name in r["methods"]]
        uniformity = [u for s in seqs for u in s["uniformity"]]
        matches = [c for s in seqs for c in s["matches"]]
        with_pairs = [s["matches"] for s in seqs if s["matches"]]
        curve = success_curve(with_pairs, taus) if with_pairs else None
        rates[name] = None if curve is None else [float(v) for v in curve]
        summary[name] = {
            "n_runs": len(seqs),
            "n_runs_with_pairs": len(with_pairs),
            "n_images": sum(s["n_images"] for s in seqs),
            "median_uniformity": float(np.median(uniformity)) if uniformity else None,
            "median_matches": float(np.median(matches)) if matches else None,
            "quartiles_matches": [float(q) for q in np.percentile(matches, [25, 75])] if matches else None,
            "min_matches": int(min(matches)) if matches else None,
            "success_at_100": float(success_curve(with_pairs, [100])[0]) if with_pairs else None,
        }
    return summary, rates
