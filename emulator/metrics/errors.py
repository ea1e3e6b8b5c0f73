"""Exceptions of the benchmark metrics (features, stereo VO, RPE).

All derive from :class:`emulator.errors.ExposimError`, so the command line turns them
into one line on stderr and exit code 1.  Every message names the offending file or
argument and says what is wrong.
"""

from __future__ import annotations

from emulator.errors import ExposimError

__all__ = ["MetricsError", "RunFolderError", "CalibrationError", "TrajectoryError"]


class MetricsError(ExposimError):
    """Invalid input to a benchmark metric (parameters, image shapes, empty data)."""


class RunFolderError(MetricsError):
    """A run folder written by ``exposim run`` is missing files or holds no images."""


class CalibrationError(MetricsError):
    """A stereo calibration file is malformed or does not match the images."""


class TrajectoryError(MetricsError):
    """A trajectory file is malformed, or two trajectories cannot be associated."""
