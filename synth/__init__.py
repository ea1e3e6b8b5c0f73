"""exposim's synthetic layer: a forward camera model and a bracket-cycle capture writer.

* :class:`Camera` + :func:`capture` turn HDR radiance into raw Bayer DN the way a
  machine-vision camera does (response, shot and read noise, vignetting, mosaic,
  quantisation, clipping), with an exact noiseless mode: the camera's parameters in
  :mod:`synth.camera`, the model in :mod:`synth.imaging`, its noise and quantiser in
  :mod:`synth.sensor`, the presets in :mod:`synth.presets`.
* :func:`capture_sequence` turns a radiance source into a BorealHDR-layout recording plus
  its ground truth (:mod:`synth.sequence`).
* :mod:`synth.procedural` makes HDR radiance without Mitsuba (a textured chart, and a
  camera walking past it); :mod:`synth.response_fit` holds the BorealHDR response fit.

Imports only :mod:`emulator` from this project.
"""

from synth import procedural
from synth.camera import Camera
from synth.imaging import capture
from synth.presets import PRESETS
from synth.sensor import noise_model_g
from synth.sequence import (
    BASELINE_M,
    BRACKETS_MS,
    FPS,
    Shot,
    capture_sequence,
    load_camera,
    shot_schedule,
)
from synth.errors import CameraError, RadianceError, SourceError, SynthError

__all__ = [
    "Camera",
    "capture",
    "capture_sequence",
    "shot_schedule",
    "Shot",
    "load_camera",
    "noise_model_g",
    "procedural",
    "PRESETS",
    "BRACKETS_MS",
    "FPS",
    "BASELINE_M",
    "SynthError",
    "CameraError",
    "RadianceError",
    "SourceError",
]
