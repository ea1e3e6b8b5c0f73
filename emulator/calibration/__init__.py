"""Inverse camera response calibration: from a static stack, or in situ from a recording.

Two estimators of g = f^-1 (DN -> linear exposure), both written as a pcalib table
(256 samples over DN ``0..table_top``, g(table_top) = 255) that
:meth:`CameraResponse.from_pcalib` reads, and a score of a response on a recording:

* :mod:`~emulator.calibration.stack_engel2016`: a static stack at several exposure times
  (:func:`calibrate_stack`, :func:`fit_inverse_response`; Engel, Usenko and Cremers 2016),
  with :mod:`~emulator.calibration.exposure_check`, which names an image whose exposure
  time does not fit the others;
* :mod:`~emulator.calibration.insitu_grossberg2003`: a recording's own bracket sweeps
  (:func:`calibrate_from_recording`, :func:`comparagram_pairs`, :func:`fit_comparametric`;
  Grossberg and Nayar 2003);
* :mod:`~emulator.calibration.solver`: the shared numerics (knot basis, monotone
  projection, Huber weights, the eigenvector solvers);
* :mod:`~emulator.calibration.scoring`: cross-bracket emulation error on a recording
  (:func:`cross_bracket_error`) and the error against a known response
  (:func:`response_error`);
* :mod:`~emulator.calibration.result`: :class:`CalibrationResult` and shared helpers.

Errors are :class:`emulator.errors.CalibrationError`.  Library code never prints; long
loops take a ``progress(done, total, label)`` callable.
"""

from emulator.calibration.insitu_grossberg2003 import calibrate_from_recording, comparagram_pairs, fit_comparametric
from emulator.calibration.result import CalibrationResult, bayer_subsample, table_top_for
from emulator.calibration.scoring import DEFAULT_QUANTILES, CrossBracketError, cross_bracket_error, response_error
from emulator.calibration.stack_engel2016 import calibrate_stack, estimate_noise_dn, fit_inverse_response

__all__ = [
    "CalibrationResult",
    "fit_inverse_response",
    "calibrate_stack",
    "comparagram_pairs",
    "fit_comparametric",
    "calibrate_from_recording",
    "CrossBracketError",
    "cross_bracket_error",
    "bayer_subsample",
    "estimate_noise_dn",
    "response_error",
    "table_top_for",
    "DEFAULT_QUANTILES",
]
