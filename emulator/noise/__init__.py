"""Sensor noise for exposure emulation: the noise model, noise-consistent tables, in-situ estimation.

An emulated image carries its source bracket's noise scaled by the exposure ratio, not the
noise a capture at the target exposure would have (issue 14).  This package holds what the
emulator needs to correct that (:func:`emulator.core.emulate` with ``noise="consistent"``):

* :mod:`~emulator.noise.model`: :class:`NoiseModel` (conversion gain, read noise, full
  well; the sensor model in its docstring) and its JSON text;
* :mod:`~emulator.noise.tables`: the per-ratio :class:`NoiseTables`, the exact quantiser
  and the noise kernel (:func:`consistent_noise`, :func:`excess_map`);
* :mod:`~emulator.noise.insitu` (with :mod:`~emulator.noise.photon_transfer`): the
  estimate of the noise figures from a recording's own brackets (:func:`bracket_groups`,
  :func:`estimate_noise_model`);
* :mod:`~emulator.noise.variance`: the measured variance ratio of emulated against live
  images (:func:`noise_variance_ratio`).

Noise-model files are read and written by :mod:`emulator.io.noisemodel`.  numpy and
OpenCV only.
"""

from emulator.noise.insitu import BracketGroup, NoiseEstimate, bracket_groups, estimate_noise_model
from emulator.noise.model import PHASES, NoiseModel, NoiseModelError, json_safe, response_fingerprint
from emulator.noise.tables import NoiseTables, check_rng, consistent_noise, excess_map, quantise, standard_normal
from emulator.noise.variance import VarianceRatio, noise_variance_ratio

__all__ = [
    "NoiseModel",
    "NoiseModelError",
    "NoiseTables",
    "BracketGroup",
    "bracket_groups",
    "NoiseEstimate",
    "estimate_noise_model",
    "response_fingerprint",
    "noise_variance_ratio",
    "VarianceRatio",
    "check_rng",
    "standard_normal",
    "quantise",
    "consistent_noise",
    "excess_map",
    "json_safe",
    "PHASES",
]
