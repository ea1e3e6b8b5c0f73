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
from emulator.core.response import CameraResponse

__all__ = ["write_noise_model", "read_noise_model", "noise_model_from_metadata"]


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


def noise_model_from_metadata(metadata: dict, response: CameraResponse, *, source: str = "exposim.json"):
    """The noise model a recording's ``exposim.json`` carries, or None when it carries none.

    Either a ``"noise_model"`` entry (:meth:`NoiseModel.to_dict` form, checked against
    ``response``), or the synthetic camera's ``"camera"`` entry written by ``synth``: gain
    ``1 / derived.h_per_electron`` and ``read_noise_e``, as ``synth.noise_model.noise_model_of``
    builds it (emulator does not import synth).  ``source`` (the file) prefixes every error.
    """
    if not isinstance(metadata, dict):
        return None
    try:
        if isinstance(metadata.get("noise_model"), dict):
            return NoiseModel.from_dict(metadata["noise_model"], response)
        camera = metadata.get("camera")
        if not isinstance(camera, dict):
            return None
        h = (camera.get("derived") or {}).get("h_per_electron")
        if h is None or "read_noise_e" not in camera:
            return None
        try:
            gain = 1.0 / float(h)
        except (TypeError, ValueError, ZeroDivisionError):
            raise NoiseModelError(f"camera.derived.h_per_electron must be a positive number, got {h!r}") from None
        return NoiseModel(response, gain, camera["read_noise_e"], f"synth:{camera.get('name', 'camera')}")
    except NoiseModelError as exc:
        raise NoiseModelError(f"{source}: {exc}") from None
