"""The synthetic camera's noise figures as an emulator noise model.

:func:`noise_model_of` turns a :class:`synth.Camera` into the
:class:`emulator.noise.NoiseModel` that noise-consistent emulation
(``emulator.core.emulate(..., noise="consistent")``) and the in-situ estimator speak: the
camera's electrons are ``h / h_per_electron`` with ``h = g(DN)``, so the conversion gain is
``1 / h_per_electron = full_well_e / g(white_level)`` electrons per unit of h, exactly; the
read noise is the camera's.  Shot noise, read noise, quantisation and clipping are then the
same model on both sides (:mod:`synth.imaging`, steps 2-4).
"""

from __future__ import annotations

from emulator.noise import NoiseModel
from synth.camera import Camera
from synth.errors import SynthError

__all__ = ["noise_model_of"]


def noise_model_of(camera: Camera) -> NoiseModel:
    """The exact noise model of ``camera`` (gain ``1 / h_per_electron``, its read noise and response)."""
    if not isinstance(camera, Camera):
        raise SynthError(f"camera must be a synth.Camera, got {type(camera).__name__}")
    return NoiseModel(camera.response, 1.0 / camera.h_per_electron, camera.read_noise_e, f"synth:{camera.name}")
