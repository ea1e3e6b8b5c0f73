"""The feature and VO benchmarks over run folders: compute, then write results.

:func:`bench_features` and :func:`bench_vo` are what ``exposim bench features|vo`` call.
Each writes into its output folder ``results.json`` (every number, and the arrays
behind the figures), PNG figures drawn by :mod:`emulator.report.bench`, and
``report.md``.  They refuse an output folder that already holds ``results.json``
unless ``force`` is given, and check every input (run folders, calibration, image size,
reference overlap) before the long computation starts.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from emulator.errors import MetricsError, RunFolderError
from emulator.io.files import REPORT_FILE, RESULTS_FILE, prepare_output, write_results, write_text
from emulator.io.runfolder import MethodRun, RunFolder, read_run_folder
from emulator.io.tum import write_tum
from emulator.metrics.features import (
    DEFAULT_TAUS,
    GRID_CELLS,
    RATIO_TEST,
    analyse_sequence,
    load_gray8,
    success_curve,
)
from emulator.metrics.stereo import (
    find_calibration,
    load_stereo_calibration,
    stereo_rectification,
)
from emulator.metrics.trajectory import associate, trajectory_from_poses
from emulator.metrics.vo import VOParameters, run_stereo_vo
from emulator.metrics.vobench import (CONVERSION, SYNTHETIC_REFERENCE, add_rpe, aligned_for_plot, calibration_record,
                                      reference_and_deltas, reference_over_run, refined_extrinsics, vo_entry,
                                      vo_parameters_record)

__all__ = [
    "bench_features",
    "bench_vo",
    "CONVERSION",
    "FAILURE_POLICY",
    "DEFAULT_DELTA_FRACTIONS",
    "REFERENCE_MAX_DIFF_S",
    "SYNTHETIC_REFERENCE",
]

#: What happens when the VO loses track, as stated in the results.
FAILURE_POLICY = (
    "a frame that fails (too few stereo points, too few matches, PnP failure, too few inliers, "
    "implausible jump) keeps the previous motion (constant velocity) and tracking restarts from its own "
    "stereo points; a run with any failed frame is marked failed and, like the paper, its RPE is not "
    "computed unless asked (rpe_on_failure)."
)
#: RPE pair lengths as fractions of the reference path length over the run (Fig. 6 x axis).
DEFAULT_DELTA_FRACTIONS = (0.1, 0.2, 0.3, 0.4, 0.5)
#: Association tolerance between run images and the reference, seconds: over half the
#: period of a 10 Hz lidar reference, so every image inside the reference's time span is
#: associated; the reference is then interpolated at the image times.
REFERENCE_MAX_DIFF_S = 0.06


def _version() -> str:
    from emulator.version import __version__

    return __version__


def _progress(iterable, progress: bool, desc: str, total: int):
    from tqdm import tqdm

    return tqdm(iterable, desc=desc, total=total, unit="img", disable=not progress, leave=False)


def _frames(method: MethodRun, max_frames: int | None):
    frames = method.frames
    if max_frames is not None:
        if max_frames < 2:
            raise MetricsError(f"max_frames must be at least 2, got {max_frames}")
        frames = frames[:max_frames]
    return frames


# --------------------------------------------------------------------------- features


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
    taus: Sequence[int] = DEFAULT_TAUS,
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
    taus : sequence of int
        Thresholds of the success curve.
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
    runs: list[RunFolder] = [read_run_folder(d, list(methods) if methods else None) for d in run_dirs]
    parameters = {
        "grid": [int(grid[0]), int(grid[1])],
        "ratio": ratio,
        "n_features": n_features,
        "matcher": matcher,
        "scale": scale,
        "max_frames": max_frames,
        "seed": seed,
        "conversion": CONVERSION,
        "sift": "cv2.SIFT_create defaults: nOctaveLayers=3, contrastThreshold=0.04, edgeThreshold=10, sigma=1.6",
    }
    run_results = []
    for run in runs:
        per_method = {}
        for name, method in run.methods.items():
            frames = _frames(method, max_frames)
            images = (
                (f.timestamp_ns, f.exposure_ms, load_gray8(f.left, white_level=run.white_level,
                                                           black_level=run.black_level))
                for f in _progress(frames, progress, f"features {name}", len(frames))
            )
            seq = analyse_sequence(images, grid=grid, ratio=ratio, n_features=n_features, matcher=matcher,
                                   scale=scale, seed=seed)
            per_method[name] = seq.to_dict()
        run_results.append({
            "run_dir": str(run.path),
            "sequence": None if run.sequence is None else str(run.sequence),
            "white_level": run.white_level,
            "black_level": run.black_level,
            "methods": per_method,
        })
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
    results = {
        "benchmark": "features",
        "exposim_version": _version(),
        "command": command,
        "parameters": parameters,
        "n_runs": len(run_results),
        "methods": summary,
        "success_curve": {"taus": taus, "rate": rates},
        "runs": run_results,
        "figures": {"fig4": "fig4_features.png"},
        "report": "report.md",
    }
    from emulator.report import bench as report

    report.plot_features(results, out / "fig4_features.png")
    write_text(out / REPORT_FILE, report.features_report(results, "fig4_features.png"))
    write_results(out / RESULTS_FILE, results)
    return results


# --------------------------------------------------------------------------- VO


def bench_vo(
    run_dir: str | Path,
    out_dir: str | Path,
    *,
    reference: str | Path | None = None,
    calibration: str | Path | None = None,
    methods: Sequence[str] | None = None,
    parameters: VOParameters = VOParameters(),
    scale: float = 1.0,
    baseline_m: float | None = None,
    refine_extrinsics: int = 0,
    deltas_m: Sequence[float] | None = None,
    delta_fractions: Sequence[float] = DEFAULT_DELTA_FRACTIONS,
    align_scale: bool = True,
    rel_delta_tol: float = 0.1,
    max_diff_s: float = REFERENCE_MAX_DIFF_S,
    rpe_on_failure: bool = False,
    max_frames: int | None = None,
    force: bool = False,
    progress: bool = False,
    command: str | None = None,
) -> dict:
    """Stereo VO on every method's images of a run, and its RPE against a reference (Fig. 6).

    Parameters
    ----------
    run_dir : path
        Run folder of ``exposim run`` with left and right images saved.
    out_dir : path
        Output folder: ``<method>/trajectory.txt`` (TUM, left camera, camera-to-world,
        first frame at the origin), ``results.json``, ``fig6_rpe.png``,
        ``trajectories.png``, ``report.md``.
    reference : path, optional
        Reference trajectory (TUM, camera-to-world of the left camera, OpenCV axes);
        default: ``<sequence>/ground_truth/poses_left.txt`` when the sequence has one;
        otherwise no RPE.
    calibration : path, optional
        Folder with ``left.yaml`` and ``right.yaml``; default ``<sequence>/calibration``.
    methods : sequence of str, optional
    parameters : VOParameters
    scale : float
        Size of the rectified images relative to the originals, (0, 1].
    baseline_m : float, optional
        Override the calibration's baseline, metres.
    refine_extrinsics : int
        When > 0, re-estimate the rig's relative rotation (and baseline direction) from
        left-right matches of this many stereo pairs, spread over the first method's
        frames (:func:`emulator.metrics.stereo.estimate_stereo_extrinsics`), and rectify with
        it.  Needed for the BorealHDR September 2023 files (identity rotation, while the
        rig is pitched by about 0.8 deg).  0 (default) uses the calibration as given.
    deltas_m : sequence of float, optional
        RPE pair lengths in metres; default ``delta_fractions`` of the reference path
        length over the run's time span.
    align_scale : bool
        Correct the estimate's scale before RPE (the paper's evo scale alignment).
    rel_delta_tol : float
        Relative tolerance on the pair length.
    max_diff_s : float
        Association tolerance between image and reference timestamps, seconds; the
        reference is interpolated at the image times (evo ``SyncMethod.interpolation``).
    rpe_on_failure : bool
        Also compute the RPE of runs where the VO failed (marked as such).
    max_frames : int, optional
        Use only the first ``max_frames`` frames of each method.
    force, progress, command
        See :func:`bench_features`.

    Returns
    -------
    dict
        The content of ``results.json``.
    """
    out = prepare_output(out_dir, force=force)
    run = read_run_folder(run_dir, list(methods) if methods else None, require_right=True)
    calib_dir = find_calibration(run.sequence, calibration)
    calib = load_stereo_calibration(calib_dir, baseline_m=baseline_m)
    selected = {name: _frames(m, max_frames) for name, m in run.methods.items()}
    for name, frames in selected.items():
        first = load_gray8(frames[0].left, white_level=run.white_level, black_level=run.black_level)
        calib.check_image_shape(first.shape, frames[0].left)
        if len(frames) < 2:
            raise RunFolderError(f"{run.methods[name].directory}: VO needs at least two frames, found {len(frames)}")
    ref_path, ref_source, ref_traj, deltas = reference_and_deltas(run, selected, reference, deltas_m,
                                                                   delta_fractions, max_diff_s)
    calib, extrinsics = refined_extrinsics(calib, run, selected, refine_extrinsics, parameters.seed)
    rect = stereo_rectification(calib, scale=scale)

    method_results, aligned_xyz, ref_xyz = {}, {}, None
    for name, frames in selected.items():
        stream = (
            (f.timestamp_ns,
             load_gray8(f.left, white_level=run.white_level, black_level=run.black_level),
             load_gray8(f.right, white_level=run.white_level, black_level=run.black_level))
            for f in _progress(frames, progress, f"VO {name}", len(frames))
        )
        vo = run_stereo_vo(stream, rect, parameters)
        write_tum(out / name / "trajectory.txt", vo.timestamps_ns, vo.poses)
        entry = vo_entry(vo, name)
        est = trajectory_from_poses(vo.timestamps_ns, vo.poses, name)
        if ref_traj is None:
            entry["rpe_skipped"] = "no reference"
            aligned_xyz[name] = est.positions_xyz
        else:
            ref_s, est_s = associate(ref_traj, est, max_diff_s=max_diff_s, interpolate=True,
                                     ref_name=str(ref_path), est_name=name)
            if vo.succeeded or rpe_on_failure:
                add_rpe(entry, ref_s, est_s, deltas, vo.succeeded, align_scale=align_scale,
                         rel_delta_tol=rel_delta_tol)
            else:
                entry["rpe_skipped"] = "VO failed (see failures); rerun with rpe_on_failure to compute it anyway"
            aligned_xyz[name] = aligned_for_plot(est_s, ref_s)
            if ref_xyz is None or ref_s.num_poses > len(ref_xyz):
                ref_xyz = ref_s.positions_xyz
        method_results[name] = entry

    if ref_xyz is not None:  # plot the whole reference over the run's span, in its own frame
        ref_xyz = reference_over_run(ref_traj, method_results, max_diff_s)
    results = {
        "benchmark": "vo",
        "exposim_version": _version(),
        "command": command,
        "run_dir": str(run.path),
        "sequence": None if run.sequence is None else str(run.sequence),
        "reference": None if ref_path is None else str(ref_path),
        "reference_source": ref_source,
        "calibration": calibration_record(calib_dir, calib, rect, extrinsics),
        "parameters": vo_parameters_record(parameters, scale=scale, align_scale=align_scale,
                                           rel_delta_tol=rel_delta_tol, deltas=deltas, deltas_m=deltas_m,
                                           delta_fractions=delta_fractions, max_diff_s=max_diff_s,
                                           rpe_on_failure=rpe_on_failure, max_frames=max_frames),
        "failure_policy": FAILURE_POLICY,
        "n_runs": len(method_results),
        "n_failed": sum(1 for m in method_results.values() if m["status"] != "success"),
        "methods": method_results,
        "figures": {"fig6": "fig6_rpe.png", "trajectories": "trajectories.png"},
        "report": "report.md",
    }
    from emulator.report import bench as report

    report.plot_rpe(results, out / "fig6_rpe.png")
    report.plot_trajectories(aligned_xyz, ref_xyz if ref_traj is not None else None, out / "trajectories.png")
    write_text(out / REPORT_FILE,
               report.vo_report(results, {"RPE against trajectory length (Fig. 6)": "fig6_rpe.png",
                                          "trajectories": "trajectories.png"}))
    write_results(out / RESULTS_FILE, results)
    return results
