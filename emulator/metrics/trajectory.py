"""Trajectories for the RPE: evo ``PoseTrajectory3D`` from TUM files or pose arrays, and time association.

Trajectories are TUM text files, ``timestamp_s tx ty tz qx qy qz qw``, camera-to-world,
read and written by :mod:`emulator.io.tum`; :func:`trajectory_from_tum` turns one into
the evo trajectory ``evo.tools.file_interface.read_tum_trajectory_file`` would give.
evo is imported only inside the functions.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from emulator.errors import TrajectoryError
from emulator.io.tum import TumTrajectory, read_tum

__all__ = [
    "read_trajectory",
    "trajectory_from_tum",
    "trajectory_from_poses",
    "associate",
    "EVO_T_MAX_DIFF_S",
]

#: evo_rpe's default maximum timestamp difference for association, seconds.
EVO_T_MAX_DIFF_S = 0.01


def trajectory_from_tum(tum: TumTrajectory):
    """The evo ``PoseTrajectory3D`` of a TUM file, as ``evo_rpe`` reads it.

    Same as ``evo.tools.file_interface.read_tum_trajectory_file``: timestamps, positions
    and quaternions as written (w moved to the front), the name the file's stem.
    """
    from evo.core.trajectory import PoseTrajectory3D

    quat_wxyz = np.roll(tum.quaternions_xyzw, 1, axis=1)
    return PoseTrajectory3D(tum.positions, quat_wxyz, tum.timestamps_s, name=Path(tum.path).stem)


def read_trajectory(path):
    """The evo trajectory of a TUM file (:func:`emulator.io.tum.read_tum`, then :func:`trajectory_from_tum`).

    Raises
    ------
    TrajectoryError
        When the file is missing, malformed, empty, or its timestamps do not increase.
    """
    try:
        return trajectory_from_tum(read_tum(path))
    except FileNotFoundError:
        raise TrajectoryError(f"{path}: trajectory file does not exist") from None


def trajectory_from_poses(timestamps_ns: Sequence[int], poses: np.ndarray, name: str = ""):
    """An evo ``PoseTrajectory3D`` from (N, 4, 4) camera-to-world poses and ns timestamps."""
    from evo.core.trajectory import PoseTrajectory3D

    stamps = np.asarray(timestamps_ns, dtype=np.int64).astype(np.float64) / 1e9
    traj = PoseTrajectory3D(poses_se3=list(np.asarray(poses, dtype=np.float64)), timestamps=stamps)
    traj.name = name
    return traj


def associate(traj_ref, traj_est, *, max_diff_s: float = EVO_T_MAX_DIFF_S, interpolate: bool = False,
              ref_name: str = "reference", est_name: str = "estimate"):
    """Associate two trajectories by time with ``evo.core.sync.associate_trajectories``.

    Parameters
    ----------
    traj_ref, traj_est : evo.core.trajectory.PoseTrajectory3D
    max_diff_s : float
        Largest time difference of an associated pair, seconds.
    interpolate : bool
        Resample the denser trajectory at the times of the sparser one (evo's
        ``SyncMethod.interpolation``) instead of taking the nearest pose.
    ref_name, est_name : str
        Names for error messages (file paths).

    Returns
    -------
    tuple
        (reference, estimate), synchronised copies of equal length.

    Raises
    ------
    TrajectoryError
        When no timestamps overlap within ``max_diff_s``.
    """
    from evo.core import sync
    from evo.core.sync_method import SyncMethod

    method = SyncMethod.interpolation if interpolate else SyncMethod.nearest_time
    try:
        ref, est = sync.associate_trajectories(traj_ref, traj_est, sync_method=method, max_diff=max_diff_s)
    except sync.SyncException:
        r0, r1 = traj_ref.timestamps[0], traj_ref.timestamps[-1]
        e0, e1 = traj_est.timestamps[0], traj_est.timestamps[-1]
        raise TrajectoryError(
            f"{ref_name} and {est_name}: no timestamps overlap within {max_diff_s} s (reference spans "
            f"{r0:.3f}..{r1:.3f} s, estimate {e0:.3f}..{e1:.3f} s; timestamps in seconds expected)"
        ) from None
    return ref, est
