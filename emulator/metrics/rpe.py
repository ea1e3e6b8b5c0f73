"""Relative pose error through evo (paper section V-D-2, Fig. 6).

Trajectories (TUM files, pose arrays) and their time association are in
:mod:`emulator.metrics.trajectory`.

Two entry points:

* :func:`rpe_files` reproduces ``evo_rpe tum REF EST --pose_relation trans_part`` exactly
  (same reader, same nearest-time association with ``--t_max_diff 0.01``, same
  ``evo.main_rpe.rpe`` call; ``align_scale`` is evo's ``--correct_scale``).
* :func:`rpe_by_length` gives the RPE as a function of the travelled distance, like the
  paper's Fig. 6: for each distance ``delta`` (metres of *reference* path), all pose pairs
  whose reference path length is within 10 % of ``delta`` (evo's ``all_pairs`` mode with
  ``pairs_from_reference``); the translation error of a pair is its evo RPE translation
  part in percent of the pair's reference path length, the rotation error its evo RPE
  angle in degrees per metre of that length.  The estimate's scale is first corrected to
  the reference's (evo's ``correct_scale`` without SE(3) alignment, "the scale alignment
  feature from the evo library" of the paper); RPE does not depend on the world frame.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from emulator.errors import MetricsError, TrajectoryError
from emulator.metrics.trajectory import EVO_T_MAX_DIFF_S, associate, read_trajectory
from emulator.io.tum import read_tum_comments

__all__ = [
    "rpe_files",
    "rpe_by_length",
    "looks_like_estimate",
    "ESTIMATE_HEADER",
    "DELTA_UNITS",
    "pair_segments",
]

#: Delta units of :func:`rpe_files`: metres of travelled path or frames.
DELTA_UNITS = ("m", "f")


def rpe_files(
    ref_path: str | Path,
    est_path: str | Path,
    *,
    delta: float = 1,
    delta_unit: str = "f",
    align_scale: bool = False,
    max_diff_s: float = EVO_T_MAX_DIFF_S,
) -> dict:
    """Translation RPE of two TUM files, exactly as ``evo_rpe`` computes it.

    Equivalent to ``evo_rpe tum REF EST --pose_relation trans_part --delta D --delta_unit
    U [--correct_scale] --t_max_diff max_diff_s``: evo reads both files, associates them
    by nearest timestamp, optionally corrects the estimate's scale (Umeyama Sim(3) scale
    only), and computes the RPE over consecutive pairs ``delta`` apart (pairs taken on the
    estimate, evo's default).

    Parameters
    ----------
    ref_path, est_path : str or pathlib.Path
        Reference and estimate TUM files, in evo's order (``evo_rpe tum REF EST``).
    delta : float
        Pair spacing, in ``delta_unit``.
    delta_unit : {"f", "m"}
        Frames or metres of travelled path.
    align_scale : bool
        Correct the estimate's scale first (evo's ``--correct_scale``).
    max_diff_s : float
        Association tolerance, seconds (evo's ``--t_max_diff``).

    Returns
    -------
    dict
        ``rmse``, ``mean``, ``median``, ``std``, ``min``, ``max`` in metres, ``n_pairs``,
        and ``scale`` (1.0 without ``align_scale``).
    """
    from evo.core import metrics
    from evo.main_rpe import rpe

    if delta_unit not in DELTA_UNITS:
        raise MetricsError(f"delta_unit must be one of {DELTA_UNITS}, got {delta_unit!r}")
    if not delta > 0:
        raise MetricsError(f"delta must be positive, got {delta}")
    if delta_unit == "f" and float(delta) != int(delta):
        raise MetricsError(f"delta must be an integer number of frames, got {delta}")
    ref = read_trajectory(ref_path)
    est = read_trajectory(est_path)
    n_ref, n_est = int(ref.num_poses), int(est.num_poses)
    # evo_rpe: traj_ref.sync_with(traj_est, nearest_time, max_diff, offset 0), which is
    # sync.associate_trajectories(ref, est, ...), wrapped here for a clear error.
    ref, est = associate(ref, est, max_diff_s=max_diff_s, ref_name=str(ref_path), est_name=str(est_path))
    unit = metrics.Unit.frames if delta_unit == "f" else metrics.Unit.meters
    try:
        result = rpe(
            traj_ref=ref,
            traj_est=est,
            pose_relation=metrics.PoseRelation.translation_part,
            delta=int(delta) if delta_unit == "f" else float(delta),
            delta_unit=unit,
            correct_scale=align_scale,
        )
    except Exception as exc:  # evo's FilterException / MetricsException
        raise TrajectoryError(f"{est_path} vs {ref_path}: RPE failed: {exc}") from None
    stats = {k: float(v) for k, v in result.stats.items()}
    scale = 1.0
    if align_scale:
        sim3 = result.np_arrays["alignment_transformation_sim3"]
        scale = float(np.cbrt(np.linalg.det(sim3[:3, :3])))
    return {
        "rmse": stats["rmse"],
        "mean": stats["mean"],
        "median": stats["median"],
        "std": stats["std"],
        "min": stats["min"],
        "max": stats["max"],
        "n_pairs": int(result.np_arrays["error_array"].size),
        "scale": scale,
        "n_ref_poses": n_ref,
        "n_est_poses": n_est,
    }


#: First comment line of the trajectories ``bench vo`` writes (see :func:`looks_like_estimate`).
ESTIMATE_HEADER = "# exposim bench vo estimate"


def looks_like_estimate(path: str | Path) -> str | None:
    """Why a TUM file is an odometry estimate rather than a reference, or None.

    Only the header that ``exposim bench vo`` writes on its estimates counts: a first pose
    at exactly the identity is no evidence, since a synthetic or re-based reference starts
    there as often as a VO estimate does.
    """
    comments = read_tum_comments(Path(path))
    if comments and ("# " + comments[0]).startswith(ESTIMATE_HEADER):
        return "it was written by exposim bench vo as an estimate"
    return None


def pair_segments(first_index, second_index) -> np.ndarray:
    """The segment of each RPE pose pair: the stretch of the run it starts in.

    Segments are consecutive runs of start poses as long as the median pair (in poses), so
    a pair overlaps at most its own and the next segment; the segments are the units of
    the RPE's block bootstrap (:func:`emulator.core.stats.compare_methods_by_segment`).

    >>> pair_segments([0, 1, 2, 3, 4, 5], [3, 4, 5, 6, 7, 8]).tolist()
    [0, 0, 0, 1, 1, 1]
    """
    a = np.asarray(first_index, dtype=np.int64)
    b = np.asarray(second_index, dtype=np.int64)
    if a.size == 0:
        return a
    span = max(1, int(np.median(b - a)))
    return a // span


def _stats(values: np.ndarray) -> dict:
    return {
        "median": float(np.median(values)),
        "mean": float(np.mean(values)),
        "rmse": float(np.sqrt(np.mean(values**2))),
        "max": float(np.max(values)),
    }


def rpe_by_length(
    traj_ref,
    traj_est,
    deltas_m: Sequence[float],
    *,
    align_scale: bool = True,
    rel_delta_tol: float = 0.1,
    evo_results: list | None = None,
) -> dict:
    """RPE as a function of travelled distance (paper Fig. 6), through evo.

    Parameters
    ----------
    traj_ref, traj_est : evo.core.trajectory.PoseTrajectory3D
        Associated trajectories of equal length (see :func:`associate`); not modified.
    deltas_m : sequence of float
        Path lengths of the pose pairs, metres of reference path.
    align_scale : bool
        Correct the estimate's scale first (Umeyama Sim(3) scale, evo's
        ``correct_scale`` without alignment).
    rel_delta_tol : float
        A pair is used when its reference path length is within ``rel_delta_tol * delta``
        of ``delta``.
    evo_results : list, optional
        When given, receives ``(relation, delta_m, evo.core.result.Result)`` for every
        delta with pairs, ``relation`` ``"trans"`` (metres) or ``"rot"`` (degrees): evo's
        own result objects, with both trajectories, for
        ``evo.tools.file_interface.save_res_file`` (``evo_res`` reads them).

    Returns
    -------
    dict
        ``scale`` applied to the estimate, ``path_length_m`` of the reference, and
        ``deltas``: one entry per delta with ``delta_m``, ``n_pairs``, ``trans_percent``
        (translation error in % of the pair's path length: median, mean, rmse, max;
        ``trans_pct`` is a deprecated alias holding the same statistics) and
        ``rot_deg_per_m`` (rotation error in degrees per metre, same statistics); the
        statistics are None when no pair has that length; ``pairs`` (where there are
        pairs): every pair's pose indices ``first_index``, ``second_index`` and its
        ``trans_percent`` and ``rot_deg_per_m`` (for intervals, :func:`pair_segments`).

    Raises
    ------
    TrajectoryError
        When fewer than two poses are given, or the scale alignment is degenerate
        (evo's Umeyama needs positions spanning at least a plane).
    """
    from evo.core import filters, geometry, metrics

    if traj_ref.num_poses != traj_est.num_poses:
        raise MetricsError("rpe_by_length: trajectories must be associated (equal number of poses)")
    if traj_ref.num_poses < 2:
        raise TrajectoryError("rpe_by_length: fewer than two associated poses")
    est = copy.deepcopy(traj_est)
    scale = 1.0
    if align_scale:
        from evo.core.geometry import GeometryException

        try:
            _, _, scale = est.align(traj_ref, correct_scale=False, correct_only_scale=True)
        except GeometryException as exc:
            raise TrajectoryError(
                f"scale alignment (Umeyama) impossible on these {traj_ref.num_poses} poses: {exc} "
                "(a straight or static trajectory); compute the RPE without scale alignment"
            ) from None
        scale = float(scale)
    traj_est_name = getattr(traj_est, "name", None) or "estimate"
    ref_poses = traj_ref.poses_se3
    cumulative = geometry.accumulated_distances(traj_ref.positions_xyz)
    out = []
    for delta in deltas_m:
        delta = float(delta)
        if not delta > 0:
            raise MetricsError(f"deltas must be positive, got {delta}")
        entry = {"delta_m": delta, "n_pairs": 0, "trans_percent": None, "trans_pct": None, "rot_deg_per_m": None}
        errors = {}
        pending: list = []
        try:
            for relation in (metrics.PoseRelation.translation_part, metrics.PoseRelation.rotation_angle_deg):
                metric = metrics.RPE(
                    relation, delta, metrics.Unit.meters, rel_delta_tol, all_pairs=True, pairs_from_reference=True
                )
                metric.process_data((traj_ref, est))
                errors[relation] = np.asarray(metric.error, dtype=np.float64)
                if evo_results is not None:
                    res = metric.get_result(ref_name="reference", est_name=traj_est_name)
                    res.add_trajectory("reference", traj_ref)
                    res.add_trajectory(traj_est_name, est)
                    kind = "trans" if relation == metrics.PoseRelation.translation_part else "rot"
                    pending.append((kind, delta, res))
        except filters.FilterException:  # no pair of this length
            out.append(entry)
            continue
        # The same pairs evo used (deterministic), for each pair's reference path length.
        pairs = np.asarray(
            metrics.id_pairs_from_delta(ref_poses, delta, metrics.Unit.meters, rel_delta_tol, all_pairs=True)
        )
        length = cumulative[pairs[:, 1]] - cumulative[pairs[:, 0]]
        entry["n_pairs"] = int(pairs.shape[0])
        if evo_results is not None:
            evo_results.extend(pending)
        trans = errors[metrics.PoseRelation.translation_part] / length * 100.0
        rot = errors[metrics.PoseRelation.rotation_angle_deg] / length
        entry["trans_percent"] = _stats(trans)
        entry["trans_pct"] = entry["trans_percent"]  # deprecated alias of trans_percent (older readers)
        entry["rot_deg_per_m"] = _stats(rot)
        # every pair's errors, for intervals over segments of the run (pair_segments)
        entry["pairs"] = {"first_index": pairs[:, 0].tolist(), "second_index": pairs[:, 1].tolist(),
                          "trans_percent": trans.tolist(), "rot_deg_per_m": rot.tolist()}
        out.append(entry)
    return {"scale": scale, "path_length_m": float(cumulative[-1]), "deltas": out}
