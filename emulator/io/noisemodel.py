"""Noise-model files: the JSON of :class:`emulator.noise.NoiseModel` (``exposim calibrate --noise``).

The document holds the conversion gain, read noise and full well per Bayer phase, the
SHA-256 of the inverse response it was fitted through (a model read with another response
is refused), and, for an in-situ estimate, the estimate's summary under ``"estimate"``.
"""

from __future__ import annotations

import os
from pathlib import Path

from emulator.io.files import atomic_write_bytes
from emulator.noise import NoiseEstimate, NoiseModel, NoiseModelError, json_safe
from emulator.response import CameraResponse

__all__ = ["write_noise_model", "read_noise_model"]


def write_noise_model(path: str | os.PathLike, model: "NoiseModel | NoiseEstimate", *,
                      overwrite: bool = False):
    """Write a noise model (or an estimate: its model plus its summary under ``"estimate"``) as JSON.

    Atomic; refuses to replace an existing file unless ``overwrite``
    (:class:`~emulator.errors.OutputExistsError`).  Returns the path.
    """
    if isinstance(model, NoiseEstimate):
        summary = model.to_dict()
        summary.pop("model")
        text = model.model.to_json(estimate=json_safe(summary))
    elif isinstance(model, NoiseModel):
        text = model.to_json()
    else:
        raise NoiseModelError(f"expected a NoiseModel or NoiseEstimate, got {type(model).__name__}")
    return atomic_write_bytes(path, text.encode(), overwrite=overwrite)


def read_noise_model(path: str | os.PathLike, response: CameraResponse) -> "NoiseModel":
    """Read :func:`write_noise_model` output; errors name the file (missing, malformed, other response)."""
    path = Path(path)
    if not path.is_file():
        raise NoiseModelError(f"{path}: noise model file not found")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise NoiseModelError(f"{path}: cannot read ({exc})") from None
    return NoiseModel.from_json(text, response, source=str(path))
