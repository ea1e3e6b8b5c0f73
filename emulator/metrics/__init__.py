"""Benchmarks of what AE does to a VSLAM pipeline (paper section V-D).

* :mod:`~emulator.metrics.features`: SIFT uniformity, consecutive matches, success rate.
* :mod:`~emulator.metrics.stereo`: stereo calibration, rectification, extrinsics refinement.
* :mod:`~emulator.metrics.vo`: a minimal stereo VO (tracking, failure policy).
* :mod:`~emulator.metrics.trajectory`: evo trajectories from TUM files or poses, time association.
* :mod:`~emulator.metrics.rpe`: the relative pose error through evo.
* :mod:`~emulator.metrics.bench`: the benchmarks over run folders (results, figures).

Files are read and written by :mod:`emulator.io` (run folders, TUM poses, camera_info),
figures and reports drawn by :mod:`emulator.report.bench`.  evo and matplotlib are
imported only inside the functions that need them.
"""

from emulator.metrics.bench import bench_features, bench_vo
from emulator.metrics.features import (
    analyse_sequence,
    detect_sift,
    grid_occupancy,
    grid_uniformity,
    load_gray8,
    match_descriptors,
    run_succeeds,
    success_curve,
    to_gray8,
)
from emulator.metrics.rpe import rpe_by_length, rpe_files
from emulator.metrics.trajectory import associate, read_trajectory, trajectory_from_poses
from emulator.metrics.stereo import load_stereo_calibration, stereo_rectification
from emulator.metrics.vo import VOParameters, VOResult, run_stereo_vo

__all__ = [
    "bench_features",
    "bench_vo",
    "to_gray8",
    "load_gray8",
    "detect_sift",
    "grid_occupancy",
    "grid_uniformity",
    "match_descriptors",
    "run_succeeds",
    "success_curve",
    "analyse_sequence",
    "read_trajectory",
    "trajectory_from_poses",
    "associate",
    "rpe_files",
    "rpe_by_length",
    "load_stereo_calibration",
    "stereo_rectification",
    "run_stereo_vo",
    "VOParameters",
    "VOResult",
]
