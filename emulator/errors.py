"""Exceptions raised by exposim: one name per kind of failure, all defined here.

Every error a user can cause with bad input derives from :class:`ExposimError`
(itself a ``ValueError``), names the offending file or argument and says what is
wrong.  The command line turns these into one line on stderr and exit code 1.
"""

from __future__ import annotations

__all__ = [
    "ExposimError",
    "ResponseError",
    "DatasetError",
    "EmulationError",
    "OutputExistsError",
    "RunLockedError",
    "CalibrationError",
    "MetricsError",
    "RunFolderError",
    "TrajectoryError",
    "PlaybackError",
    "MissingExtraError",
]


class ExposimError(ValueError):
    """Base class of all user-facing exposim errors."""


class ResponseError(ExposimError):
    """A camera response table is malformed (count, finiteness, monotonicity)."""


class DatasetError(ExposimError):
    """A file on disk is malformed: bad PNG, unknown folder, missing camera, bad JSON, EXR, ..."""


class EmulationError(ExposimError):
    """Invalid input to the emulator (exposure, image dtype/shape, DN range)."""


class OutputExistsError(ExposimError, FileExistsError):
    """An output path exists and the caller did not ask to overwrite it."""


class RunLockedError(ExposimError):
    """A run folder is being written by another live process (its lock is held)."""


class CalibrationError(ExposimError):
    """A calibration cannot be used or made: a response calibration (too few exposures,
    clipped, moving scene, malformed stack) or a malformed stereo calibration file."""


class MetricsError(ExposimError):
    """Invalid input to a benchmark metric (parameters, image shapes, empty data)."""


class RunFolderError(MetricsError):
    """A run folder written by ``exposim run`` is missing files or holds no images."""


class TrajectoryError(MetricsError):
    """A trajectory file is malformed, or two trajectories cannot be associated."""


class PlaybackError(ExposimError):
    """A run cannot proceed: bad configuration, or a resumed run that does not match its folder."""


class MissingExtraError(ExposimError, ImportError):
    """A feature needs an optional extra that is not installed (``pip install 'exposim[NAME]'``)."""
