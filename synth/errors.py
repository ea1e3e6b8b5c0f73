"""Exceptions raised by :mod:`synth`.

All derive from :class:`emulator.errors.ExposimError` (a ``ValueError``), so the command
line reports them as one line; each message names the offending argument or file.
"""

from __future__ import annotations

from emulator.errors import ExposimError

__all__ = ["SynthError", "CameraError", "RadianceError", "SourceError", "PoseError"]


class SynthError(ExposimError):
    """Base class of the synthetic layer's errors."""


class CameraError(SynthError):
    """A camera description is invalid (levels, noise figures, vignetting, Bayer pattern)."""


class RadianceError(SynthError):
    """A radiance image is unusable: wrong shape or dtype, NaN, infinite or negative values."""


class SourceError(SynthError):
    """A radiance source returned something unusable (pose, frame count, stereo geometry)."""


class PoseError(SynthError):
    """A camera pose is not a finite rigid 4x4 camera-to-world matrix (shape, values, bottom row, rotation)."""
