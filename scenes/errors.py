"""Exceptions raised by :mod:`scenes`.

Both derive from :class:`emulator.errors.ExposimError`, so the command line turns
them into one line on stderr and exit code 1.
"""

from __future__ import annotations

from emulator.errors import ExposimError

__all__ = ["SceneError", "RenderError"]


class SceneError(ExposimError):
    """Invalid scene request: unknown scene name, unknown or out-of-range parameter."""


class RenderError(ExposimError):
    """A render could not be made: bad size or spp, no usable Mitsuba variant, bad pose."""
