"""The stereo VO benchmark over a run folder (paper Fig. 6): VO per method, RPE against a
reference, results, figures and report.  :func:`bench_vo` is what ``exposim bench vo`` calls;
:mod:`emulator.metrics.bench` re-exports every name here (split out of it by size).
"""

from __future__ import annotations

import contextlib
import copy
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np

from emulator.errors import ExposimError, MetricsError, RunFolderError, TrajectoryError
from emulator.io.borealhdr import read_recording_metadata
from emulator.io.files import RESULTS_FILE, prepare_output
from emulator.io.runfolder import RunFolder, read_run_folder
from emulator.io.tum import write_tum
from emulator.metrics.bench_common import CONVERSION, features_sheet, method_frames, progress_iter, benchmark_frames
from emulator.version import __version__
from emulator.metrics.features import load_gray8
from emulator.metrics.rpe import ESTIMATE_HEADER, pair_segments, rpe_by_length
from emulator.metrics.stereo import choose_calibration, load_stereo_calibration, stereo_rectification
from emulator.metrics.trajectory import associate, read_trajectory, trajectory_from_poses
from emulator.metrics.vo import VOParameters, run_stereo_vo
from emulator.metrics.vo_extrinsics import (  # re-exported: the extrinsics check lives in emulator.metrics.vo_extrinsics
    REFINE_PAIRS,
    REFINE_THRESHOLD_FRACTION,
    check_extrinsics,
    decide_extrinsics,
)
from emulator.metrics.vo_table import vo_ranking, vo_summary
from emulator.report.bench import write_vo_report
from emulator.core.stats import compare_methods_by_segment

__all__ = [
    "bench_vo",
    "check_extrinsics",
    "FAILURE_POLICY",
    "DEFAULT_DELTA_FRACTIONS",
    "REFERENCE_MAX_DIFF_S",
    "SYNTHETIC_REFERENCE",
    "REFINE_PAIRS",
    "REFINE_THRESHOLD_FRACTION",
    "no_reference_note",
    "evo_result_path",
    "rpe_intervals",
]

#: What happens when the VO loses track, as stated in the results.
FAILURE_POLICY = (
    "a frame that fails (too few stereo points, too few matches, PnP failure, too few inliers, "
    "implausible jump) keeps the previous motion (constant velocity) and tracking restarts from its own "
    "stereo points; a run with any failed frame is marked failed and, like the paper, its RPE is not "
    "computed unless asked (`--rpe-on-failure`, rpe_on_failure=True)."
)
#: RPE pair lengths as fractions of the reference path length over the run (Fig. 6 x axis).
DEFAULT_DELTA_FRACTIONS = (0.1, 0.2, 0.3, 0.4, 0.5)
#: Association tolerance between run images and the reference, seconds: over half the
#: period of a 10 Hz lidar reference, so every image inside the reference's time span is
#: associated; the reference is then interpolated at the image times.
REFERENCE_MAX_DIFF_S = 0.06
#: Reference that synthetic sequences write, used when no reference is given.
SYNTHETIC_REFERENCE = Path("ground_truth") / "poses_left.txt"


def no_reference_note(sequence: str | Path | None) -> str:
    """What the benchmark says when there is no reference trajectory, naming the recording used."""
    name = f"The recording {Path(sequence).name}" if sequence is not None else "The run's recording"
    return (
        f"RPE not computed: no reference trajectory. {name} has none (no {SYNTHETIC_REFERENCE.as_posix()} in it, "
        "and no --reference FILE was given). BorealHDR's "
        "reference trajectories are computed from the 3-D lidar and the IMU by a lidar-inertial SLAM based on "
        "libpointmatcher; exported as a TUM file of the left camera's poses (camera-to-world, "
        "OpenCV axes, timestamps in s) it is given with --reference FILE. Without it the "
        "VO's tracking statistics and trajectories are still computed."
    )


def _choice_record(choice, sequence) -> dict:
    """The calibration choice as results.json keeps it; a synthetic recording (written by exposim
    synth) has no recording date, whatever its timestamps decode to, and is marked ``synthetic``."""
    record = choice.to_dict()
    generator = {}
    if sequence is not None and Path(sequence).is_dir():
        with contextlib.suppress(ExposimError):
            generator = read_recording_metadata(sequence).get("generator") or {}
    if isinstance(generator, dict) and str(generator.get("name", "")).startswith("exposim"):
        record.update(recording_date=None, date_source="", synthetic=True)
    return record


def _reference_path(run: RunFolder, reference: str | Path | None) -> tuple[Path | None, str]:
    if reference is not None:
        return Path(reference), "given"
    if run.sequence is not None and (run.sequence / SYNTHETIC_REFERENCE).is_file():
        return run.sequence / SYNTHETIC_REFERENCE, "synthetic ground truth of the sequence"
    return None, "none"


def _aligned_for_plot(est, ref) -> np.ndarray:
    """Estimate positions Sim(3)-aligned to the reference (evo Umeyama), for the top view."""
    from evo.core.geometry import GeometryException

    shown = copy.deepcopy(est)
    try:
        shown.align(ref, correct_scale=True)
    except GeometryException:  # degenerate (straight) path: align the origins only
        shown.align_origin(ref)
    return shown.positions_xyz


def evo_result_path(out: Path, relation: str, delta_m: float, method: str) -> Path:
    """Where :func:`bench_vo` saves evo's result file of one method, relation and pair length:
    ``evo/rpe_<relation>_<delta>m/<method>.zip`` (``evo_res evo/rpe_trans_1.00m/*.zip``
    compares the methods at one pair length)."""
    return out / "evo" / f"rpe_{relation}_{delta_m:.2f}m" / f"{method}.zip"


def _check_inputs(run_dir, out_dir, methods, max_frames, calibration, baseline_m, force, every_frame=False):
    """The run, its frames per method, the calibration choice and the calibration, all checked."""
    if (Path(out_dir) / RESULTS_FILE).exists() and not force:
        prepare_output(out_dir, force=force)  # refuses, naming the file
    run = benchmark_frames(read_run_folder(run_dir, list(methods) if methods else None, require_right=True), every_frame)
    selected = {name: method_frames(m, max_frames) for name, m in run.methods.items()}
    first_ns = min((fr[0].timestamp_ns for fr in selected.values() if fr), default=None)
    choice = choose_calibration(run.sequence, calibration, first_ns)
    calib = load_stereo_calibration(choice.folder, baseline_m=baseline_m)
    for name, frames in selected.items():
        first = load_gray8(frames[0].left, white_level=run.white_level, black_level=run.black_level)
        calib.check_image_shape(first.shape, frames[0].left)
        if len(frames) < 2:
            raise RunFolderError(f"{run.methods[name].directory}: VO needs at least two frames, found {len(frames)}")
    return run, selected, choice, calib


def _reference_and_deltas(ref_path, run, selected, max_diff_s, deltas_m, delta_fractions, limitations):
    """The reference trajectory (None without one; checked to overlap every method's images) and the
    RPE pair lengths, m."""
    if ref_path is None:
        limitations.append(no_reference_note(run.sequence))
        return None, None
    ref_traj = read_trajectory(ref_path)
    for name, frames in selected.items():  # fail now, not after the VO: overlap check
        stamps = [f.timestamp_ns for f in frames]
        dummy = trajectory_from_poses(stamps, np.tile(np.eye(4), (len(stamps), 1, 1)))
        ref_s, _ = associate(ref_traj, dummy, max_diff_s=max_diff_s, interpolate=True,
                             ref_name=str(ref_path), est_name=f"images of {name} in {run.path}")
        if ref_s.num_poses < 2:
            raise MetricsError(f"{ref_path}: only {ref_s.num_poses} reference pose overlaps the images of {name}")
    if deltas_m is not None:
        return ref_traj, [float(d) for d in deltas_m]
    t0 = min(f.timestamp_ns for fr in selected.values() for f in fr) / 1e9
    t1 = max(f.timestamp_ns for fr in selected.values() for f in fr) / 1e9
    span = [i for i, t in enumerate(ref_traj.timestamps) if t0 - max_diff_s <= t <= t1 + max_diff_s]
    length = float(np.sum(np.linalg.norm(np.diff(ref_traj.positions_xyz[span], axis=0), axis=1)))
    if not length > 0:
        raise MetricsError(f"{ref_path}: the reference does not move during the run; give deltas_m")
    return ref_traj, [float(f) * length for f in delta_fractions]


def _vo_method(name, frames, run, rect, parameters, out, progress, ref_traj, ref_path, deltas, *, max_diff_s,
               align_scale, rel_delta_tol, rpe_on_failure):
    """One method's VO, trajectory file, RPE and evo result files: ``(entry, plotted xyz, associated
    reference or None)``."""
    stream = (
        (f.timestamp_ns,
         load_gray8(f.left, white_level=run.white_level, black_level=run.black_level),
         load_gray8(f.right, white_level=run.white_level, black_level=run.black_level))
        for f in progress_iter(frames, progress, f"VO {name}", len(frames))
    )
    vo = run_stereo_vo(stream, rect, parameters)
    write_tum(out / f"{name}.txt", vo.timestamps_ns, vo.poses,
              header=f"{ESTIMATE_HEADER[2:]}: method {name}, left camera, camera-to-world, "
              f"first frame at the origin, metres (run {run.path})")
    entry = {
        "status": "success" if vo.succeeded else "failed",
        "n_frames": int(vo.timestamps_ns.size),
        "n_tracked": int(vo.tracked.sum()),
        "failures": vo.failures_as_dicts(),
        "trajectory": f"{name}.txt",
        "evo_results": [],
        "frames": {
            "timestamps_ns": vo.timestamps_ns.tolist(),
            "tracked": vo.tracked.tolist(),
            "n_stereo_points": vo.n_stereo.tolist(),
            "n_matches": vo.n_matches.tolist(),
            "n_inliers": vo.n_inliers.tolist(),
            "row_offset_px": [None if not np.isfinite(v) else round(float(v), 3) for v in vo.row_offset_px],
        },
        "rpe": None,
        "rpe_skipped": None,
    }
    est = trajectory_from_poses(vo.timestamps_ns, vo.poses, name)
    entry["summary"] = vo_summary(entry["frames"], est.positions_xyz)
    if ref_traj is None:
        entry["rpe_skipped"] = "no reference"
        return entry, est.positions_xyz, None
    ref_s, est_s = associate(ref_traj, est, max_diff_s=max_diff_s, interpolate=True,
                             ref_name=str(ref_path), est_name=name)
    est_s.name = name
    if vo.succeeded or rpe_on_failure:
        evo_results: list = []
        try:
            entry["rpe"] = rpe_by_length(ref_s, est_s, deltas, align_scale=align_scale,
                                         rel_delta_tol=rel_delta_tol, evo_results=evo_results)
        except TrajectoryError as exc:
            entry["rpe_skipped"] = str(exc)
        else:
            entry["rpe"]["n_associated"] = int(ref_s.num_poses)
            entry["rpe"]["computed_on_failed_run"] = not vo.succeeded
            from evo.tools.file_interface import save_res_file

            for relation, delta, res in evo_results:
                path = evo_result_path(out, relation, delta, name)
                path.parent.mkdir(parents=True, exist_ok=True)
                save_res_file(path, res)
                entry["evo_results"].append(str(path.relative_to(out)))
    else:
        entry["rpe_skipped"] = ("VO failed (see failures); rerun with --rpe-on-failure "
                                "(rpe_on_failure=True) to compute it anyway")
    return entry, _aligned_for_plot(est_s, ref_s), ref_s


def rpe_intervals(method_results: dict, *, seed: int = 0) -> list[dict]:
    """Per RPE pair length: each method's median translation RPE (% of the length) with a 95 % interval
    and its difference from the best (lowest) with an interval, by a circular block bootstrap over
    segments of the run (:func:`emulator.metrics.rpe.pair_segments`,
    :func:`emulator.core.stats.compare_methods_by_segment`; methods on the same reference pairs paired).
    Methods without an RPE at that length are left out; a length no method has is left out."""
    by_delta: dict[float, dict] = {}
    for name, entry in method_results.items():
        for d in (entry.get("rpe") or {}).get("deltas", []):
            p = d.get("pairs")
            if p and p["trans_percent"]:
                by_delta.setdefault(float(d["delta_m"]), {})[name] = p
    out = []
    for k, (delta, pairs) in enumerate(sorted(by_delta.items())):
        cmp = compare_methods_by_segment({m: p["trans_percent"] for m, p in pairs.items()},
                                         {m: pair_segments(p["first_index"], p["second_index"])
                                          for m, p in pairs.items()},
                                         "median", higher_is_better=False, seed=[seed, k])
        out.append({"delta_m": delta, **cmp})
    return out


def _note_failures(method_results: dict, has_reference: bool, limitations: list[str]) -> None:
    """Add the limitation that names the method runs where the VO lost track, if any."""
    failed = {n: e for n, e in method_results.items() if e["status"] != "success"}
    if not failed:
        return
    shown = "; ".join(
        f"{n}: {len(e['failures'])} of {e['n_frames'] - 1} frame steps failed ("
        + ", ".join(sorted({f['reason'] for f in e['failures']})) + ")" for n, e in failed.items())
    no_rpe = [n for n, e in failed.items() if e["rpe"] is None and has_reference]
    limitations.append(f"VO lost track on {len(failed)} of {len(method_results)} method run(s) ({shown})"
                       + (f"; their RPE is not computed ({', '.join(no_rpe)}): pass --rpe-on-failure to compute it "
                          "anyway" if no_rpe else "") + ".")


def _calibration_record(calib, rect, choice, run: RunFolder, extrinsics_record: dict) -> dict:
    """``results["calibration"]``: the folder, the rectification and the extrinsics decision."""
    return {
        "folder": str(choice.folder),
        "baseline_m": calib.baseline_m,
        "rectified_fx_px": float(rect.K[0, 0]),
        "rectified_size": list(rect.size),
        "image_size": list(calib.image_size),
        "method": "cv2.stereoRectify from K, D of both cameras, R = R_r^T R_l, T = -R_r^T [b, 0, 0], alpha 0"
        + ("; R (pitch, roll) and the baseline direction re-estimated from left-right matches (yaw and "
           "baseline length as calibrated)" if extrinsics_record.get("estimate") else ""),
        "choice": _choice_record(choice, run.sequence),
        "extrinsics": extrinsics_record,
        "refined_extrinsics": extrinsics_record.get("estimate"),
    }


def _reference_over_run(ref_traj, method_results: dict, max_diff_s: float) -> np.ndarray:
    """The reference's positions over the run's time span (all methods' frames), for the top view."""
    t0 = min(float(vo_e["frames"]["timestamps_ns"][0]) for vo_e in method_results.values()) / 1e9
    t1 = max(float(vo_e["frames"]["timestamps_ns"][-1]) for vo_e in method_results.values()) / 1e9
    keep = (ref_traj.timestamps >= t0 - max_diff_s) & (ref_traj.timestamps <= t1 + max_diff_s)
    return ref_traj.positions_xyz[keep]


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
    refine_extrinsics: int | str = "auto",
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
    every_frame: bool = False,
) -> dict:
    """Stereo VO on every method's images of a run, and its RPE against a reference (Fig. 6).

    Parameters
    ----------
    run_dir : path
        Run folder of ``exposim run`` with left and right images saved.
    out_dir : path
        Output folder: ``<method>.txt`` per method (TUM, left camera, camera-to-world,
        first frame at the origin, named so that ``evo_traj tum OUT/*.txt`` labels them by
        method), evo result files ``evo/rpe_trans_<delta>m/<method>.zip`` and
        ``evo/rpe_rot_<delta>m/<method>.zip`` where the RPE is computed (read by
        ``evo_res``), ``results.json``, ``fig6_rpe.png``, ``trajectories.png``, ``report.md``.
    reference : path, optional
        Reference trajectory (TUM, camera-to-world of the left camera, OpenCV axes);
        default: ``<sequence>/ground_truth/poses_left.txt`` when the sequence has one;
        otherwise no RPE.
    calibration : path, optional
        Folder with ``left.yaml`` and ``right.yaml``; default: chosen from the recording's
        layout and date (:func:`emulator.metrics.stereo.choose_calibration`), recorded with
        the reason in ``results["calibration"]["choice"]``.
    methods : sequence of str, optional
    parameters : VOParameters
    scale : float
        Size of the rectified images relative to the originals, (0, 1].
    baseline_m : float, optional
        Override the calibration's baseline, metres.
    refine_extrinsics : "auto", int
        ``"auto"`` (default): measure the median epipolar residual of left-right matches of
        :data:`REFINE_PAIRS` stereo pairs under the given calibration, and re-estimate the
        rig's relative rotation (and baseline direction) from those matches
        (:func:`emulator.metrics.stereo.estimate_stereo_extrinsics`) when it exceeds
        :data:`REFINE_THRESHOLD_FRACTION` of the VO's row tolerance (the BorealHDR September
        2023 files: identity rotation, while the rig is pitched by about 0.8 deg, a 16 px
        residual).  N > 0: always refine, from N pairs.  0: the calibration as given.  The
        measurement and the decision are in ``results["calibration"]["extrinsics"]``.
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
    max_frames, every_frame
        Use only the first ``max_frames`` frames of each method; every frame of a native-rate run (default: one
        per recorder cycle, :func:`~emulator.metrics.bench_common.benchmark_frames`).
    force, progress, command
        See :func:`bench_features`.

    Returns
    -------
    dict
        The content of ``results.json``.
    """
    run, selected, choice, calib = _check_inputs(run_dir, out_dir, methods, max_frames, calibration, baseline_m, force, every_frame)
    limitations: list[str] = []
    ref_path, ref_source = _reference_path(run, reference)
    ref_traj, deltas = _reference_and_deltas(ref_path, run, selected, max_diff_s, deltas_m, delta_fractions,
                                             limitations)
    calib, extrinsics_record = decide_extrinsics(calib, next(iter(selected.values())), run, refine_extrinsics,
                                                 parameters, limitations)
    rect = stereo_rectification(calib, scale=scale)
    out = prepare_output(out_dir, force=force)

    method_results, aligned_xyz, ref_xyz = {}, {}, None
    for name, frames in selected.items():
        entry, aligned_xyz[name], ref_s = _vo_method(
            name, frames, run, rect, parameters, out, progress, ref_traj, ref_path, deltas,
            max_diff_s=max_diff_s, align_scale=align_scale, rel_delta_tol=rel_delta_tol,
            rpe_on_failure=rpe_on_failure)
        if ref_s is not None and (ref_xyz is None or ref_s.num_poses > len(ref_xyz)):
            ref_xyz = ref_s.positions_xyz
        method_results[name] = entry

    _note_failures(method_results, ref_traj is not None, limitations)
    if ref_xyz is not None:  # plot the whole reference over the run's span, in its own frame
        ref_xyz = _reference_over_run(ref_traj, method_results, max_diff_s)
    results = {
        "benchmark": "vo",
        "exposim_version": __version__,
        "command": command,
        "run_dir": str(run.path),
        "sequence": None if run.sequence is None else str(run.sequence),
        "reference": None if ref_path is None else str(ref_path),
        "reference_source": ref_source,
        "calibration": _calibration_record(calib, rect, choice, run, extrinsics_record),
        "parameters": {
            "vo": asdict(parameters),
            "scale": scale,
            "align_scale": align_scale,
            "rel_delta_tol": rel_delta_tol,
            "deltas_m": deltas,
            "delta_fractions": None if deltas_m is not None else list(delta_fractions),
            "max_diff_s": max_diff_s,
            "association": "evo sync.associate_trajectories, SyncMethod.interpolation",
            "rpe_on_failure": rpe_on_failure,
            "max_frames": max_frames,
            "conversion": CONVERSION,
        },
        "failure_policy": FAILURE_POLICY,
        "limitations": limitations,
        "n_runs": len(method_results),
        "n_failed": sum(1 for m in method_results.values() if m["status"] != "success"),
        "methods": method_results,
        "rpe_intervals": rpe_intervals(method_results, seed=parameters.seed),
        "ranking_without_reference": vo_ranking(method_results),
        "figures": ({"fig6": "fig6_rpe.png"} if ref_traj is not None else {}) | {"trajectories": "trajectories.png"},
        "report": "report.md",
    }
    write_vo_report(out, results, aligned_xyz, ref_xyz if ref_traj is not None else None,
                    features_sheet(run, None, max_frames), with_rpe=ref_traj is not None)
    return results
