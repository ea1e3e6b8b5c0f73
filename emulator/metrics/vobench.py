"""The parts of :func:`emulator.metrics.bench.bench_vo`: the reference, the rig's extrinsics, the records."""

from __future__ import annotations

import copy
from dataclasses import asdict
from pathlib import Path

import numpy as np

from emulator.errors import MetricsError, TrajectoryError
from emulator.io.runfolder import RunFolder
from emulator.metrics.features import load_gray8
from emulator.metrics.rpe import rpe_by_length
from emulator.metrics.stereo import estimate_stereo_extrinsics
from emulator.metrics.trajectory import associate, read_trajectory, trajectory_from_poses

__all__ = ["CONVERSION", "SYNTHETIC_REFERENCE", "reference_path", "aligned_for_plot", "reference_and_deltas", "refined_extrinsics", "vo_entry", "add_rpe",
           "calibration_record", "reference_over_run", "vo_parameters_record"]

#: The 12-bit to 8-bit conversion, as stated in the results.
CONVERSION = (
    "gray8 = clip(round((cv2.cvtColor(raw, COLOR_BayerRG2GRAY) - black_level) * 255 / "
    "(white_level - black_level)), 0, 255) for png16 Bayer images (emulator.gray.bayer_to_gray8); png8 images, "
    "converted by exposim run with the same function, are used as saved"
)
#: Reference that synthetic sequences write, used when no reference is given.
SYNTHETIC_REFERENCE = Path("ground_truth") / "poses_left.txt"


def reference_path(run: RunFolder, reference: str | Path | None) -> tuple[Path | None, str]:
    if reference is not None:
        return Path(reference), "given"
    if run.sequence is not None and (run.sequence / SYNTHETIC_REFERENCE).is_file():
        return run.sequence / SYNTHETIC_REFERENCE, "synthetic ground truth of the sequence"
    return None, "none"


def aligned_for_plot(est, ref) -> np.ndarray:
    """Estimate positions Sim(3)-aligned to the reference (evo Umeyama), for the top view."""
    from evo.core.geometry import GeometryException

    shown = copy.deepcopy(est)
    try:
        shown.align(ref, correct_scale=True)
    except GeometryException:  # degenerate (straight) path: align the origins only
        shown.align_origin(ref)
    return shown.positions_xyz


def reference_and_deltas(run, selected: dict, reference, deltas_m, delta_fractions, max_diff_s: float):
    """The VO reference (path, source, trajectory; Nones without one), checked to overlap every method's
    images, and the RPE pair lengths (``deltas_m``, or ``delta_fractions`` of the reference path)."""
    ref_path, ref_source = reference_path(run, reference)
    ref_traj = None
    deltas = None
    if ref_path is not None:
        ref_traj = read_trajectory(ref_path)
        for name, frames in selected.items():  # fail now, not after the VO: overlap check
            stamps = [f.timestamp_ns for f in frames]
            dummy = trajectory_from_poses(stamps, np.tile(np.eye(4), (len(stamps), 1, 1)))
            ref_s, _ = associate(ref_traj, dummy, max_diff_s=max_diff_s, interpolate=True,
                                 ref_name=str(ref_path), est_name=f"images of {name} in {run.path}")
            if ref_s.num_poses < 2:
                raise MetricsError(f"{ref_path}: only {ref_s.num_poses} reference pose overlaps the images of {name}")
        if deltas_m is None:
            t0 = min(f.timestamp_ns for fr in selected.values() for f in fr) / 1e9
            t1 = max(f.timestamp_ns for fr in selected.values() for f in fr) / 1e9
            span = [i for i, t in enumerate(ref_traj.timestamps) if t0 - max_diff_s <= t <= t1 + max_diff_s]
            length = float(np.sum(np.linalg.norm(np.diff(ref_traj.positions_xyz[span], axis=0), axis=1)))
            if not length > 0:
                raise MetricsError(f"{ref_path}: the reference does not move during the run; give deltas_m")
            deltas = [float(f) * length for f in delta_fractions]
        else:
            deltas = [float(d) for d in deltas_m]
    return ref_path, ref_source, ref_traj, deltas


def refined_extrinsics(calib, run, selected: dict, refine_extrinsics: int, seed):
    """``(calibration, extrinsics)``: re-estimated from left-right matches when ``refine_extrinsics`` > 0."""
    extrinsics = None
    if refine_extrinsics > 0:
        frames = next(iter(selected.values()))
        picks = np.unique(np.linspace(0, len(frames) - 1, min(refine_extrinsics, len(frames))).round().astype(int))
        pairs = (
            (load_gray8(frames[i].left, white_level=run.white_level, black_level=run.black_level),
             load_gray8(frames[i].right, white_level=run.white_level, black_level=run.black_level))
            for i in picks
        )
        extrinsics = estimate_stereo_extrinsics(calib, pairs, seed=seed)
        calib = calib.with_extrinsics(extrinsics.R, extrinsics.T)
    return calib, extrinsics


def vo_entry(vo, name: str) -> dict:
    """The per-method VO record of ``results.json`` (RPE fields still empty)."""
    return {
        "status": "success" if vo.succeeded else "failed",
        "n_frames": int(vo.timestamps_ns.size),
        "n_tracked": int(vo.tracked.sum()),
        "failures": vo.failures_as_dicts(),
        "trajectory": f"{name}/trajectory.txt",
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


def add_rpe(entry: dict, ref_s, est_s, deltas, succeeded: bool, *, align_scale: bool, rel_delta_tol: float) -> None:
    """Fill ``entry["rpe"]`` (or ``rpe_skipped`` with the reason) from the associated trajectories."""
    try:
        entry["rpe"] = rpe_by_length(ref_s, est_s, deltas, align_scale=align_scale, rel_delta_tol=rel_delta_tol)
    except TrajectoryError as exc:
        entry["rpe_skipped"] = str(exc)
    else:
        entry["rpe"]["n_associated"] = int(ref_s.num_poses)
        entry["rpe"]["computed_on_failed_run"] = not succeeded


def calibration_record(calib_dir, calib, rect, extrinsics) -> dict:
    """The stereo calibration a VO benchmark used, as ``results.json`` records it."""
    return {
        "folder": str(calib_dir),
        "baseline_m": calib.baseline_m,
        "rectified_fx_px": float(rect.K[0, 0]),
        "rectified_size": list(rect.size),
        "image_size": list(calib.image_size),
        "method": "cv2.stereoRectify from K, D of both cameras, R = R_r^T R_l, T = -R_r^T [b, 0, 0], alpha 0"
        + ("; R and T direction re-estimated from left-right matches" if extrinsics else ""),
        "refined_extrinsics": None if extrinsics is None else extrinsics.to_dict(),
    }


def reference_over_run(ref_traj, method_results: dict, max_diff_s: float) -> np.ndarray:
    """The reference positions over the time span of the methods' VO frames."""
    t0 = min(float(vo_e["frames"]["timestamps_ns"][0]) for vo_e in method_results.values()) / 1e9
    t1 = max(float(vo_e["frames"]["timestamps_ns"][-1]) for vo_e in method_results.values()) / 1e9
    keep = (ref_traj.timestamps >= t0 - max_diff_s) & (ref_traj.timestamps <= t1 + max_diff_s)
    return ref_traj.positions_xyz[keep]


def vo_parameters_record(parameters, *, scale, align_scale, rel_delta_tol, deltas, deltas_m, delta_fractions,
                         max_diff_s, rpe_on_failure, max_frames) -> dict:
    """The parameters of a VO benchmark, as ``results.json`` records them."""
    return {
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
    }
