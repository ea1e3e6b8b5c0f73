"""Benchmarks of what AE does to a VSLAM pipeline (paper section V-D).

* :mod:`~emulator.metrics.features`: SIFT uniformity, consecutive matches, success rate.
* :mod:`~emulator.metrics.vo`: stereo calibration, rectification, a minimal stereo VO.
* :mod:`~emulator.metrics.rpe`: TUM files and the relative pose error through evo.
* :mod:`~emulator.metrics.runfolder`: reader of the run folders of ``exposim run``.
* :mod:`~emulator.metrics.bench`: the benchmarks over run folders (results, figures).
* :mod:`~emulator.metrics.report`: figures and markdown (the only module that plots).

evo and matplotlib are imported only inside the functions that need them.
"""

from emulator.metrics.bench import bench_features, bench_vo
from emulator.metrics.errors import CalibrationError, MetricsError, RunFolderError, TrajectoryError
from emulator.metrics.features import (
    analyse_sequence,
    bayer_to_gray8,
    detect_sift,
    grid_occupancy,
    grid_uniformity,
    load_gray8,
    match_descriptors,
    run_succeeds,
    success_curve,
    to_gray8,
)
from emulator.metrics.rpe import associate, read_tum, rpe_by_length, rpe_files, trajectory_from_poses, write_tum
from emulator.metrics.runfolder import read_run_folder
from emulator.metrics.vo import (
    VOParameters,
    VOResult,
    load_stereo_calibration,
    read_camera_info,
    run_stereo_vo,
    stereo_rectification,
)

__all__ = [
    "bench_features",
    "bench_vo",
    "MetricsError",
    "RunFolderError",
    "CalibrationError",
    "TrajectoryError",
    "bayer_to_gray8",
    "to_gray8",
    "load_gray8",
    "detect_sift",
    "grid_occupancy",
    "grid_uniformity",
    "match_descriptors",
    "run_succeeds",
    "success_curve",
    "analyse_sequence",
    "read_tum",
    "write_tum",
    "trajectory_from_poses",
    "associate",
    "rpe_files",
    "rpe_by_length",
    "read_run_folder",
    "read_camera_info",
    "load_stereo_calibration",
    "stereo_rectification",
    "run_stereo_vo",
    "VOParameters",
    "VOResult",
]
