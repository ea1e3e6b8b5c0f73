"""Exceptions raised by exposim.

Every error a user can cause with bad input derives from :class:`ExposimError`
(itself a ``ValueError``), names the offending file or argument and says what is
wrong.  The command line turns these into one line on stderr and exit code 1.
"""

from __future__ import annotations

__all__ = ["ExposimError", "ResponseError", "DatasetError", "EmulationError", "OutputExistsError"]


class ExposimError(ValueError):
    """Base class of all user-facing exposim errors."""


class ResponseError(ExposimError):
    """A camera response table is malformed (count, finiteness, monotonicity)."""


class DatasetError(ExposimError):
    """A recording on disk is malformed: bad PNG, unknown folder, missing camera."""


class EmulationError(ExposimError):
    """Invalid input to the emulator (exposure, image dtype/shape, DN range)."""


class OutputExistsError(ExposimError, FileExistsError):
    """An output path exists and the caller did not ask to overwrite it."""
