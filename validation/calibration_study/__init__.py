"""Validation of the inverse-response calibration: synthetic stacks, OpenCV, in situ, real sample.

Run::

    python -m validation.calibration_study OUT [--quick] [--force]

Writes ``OUT/results.json`` (every figure, the settings and versions), ``OUT/report.md``
(the tables), ``OUT/*.png`` (plots) and ``OUT/curves.npz`` (the arrays behind them).

Parts:

1. **Static stacks** through each synthetic camera preset (``synth.Camera.preset``:
   borealhdr, linear, gamma22, s_curve), with shot and read noise, rendered from the
   ``static_lab`` Mitsuba scene (or, without Mitsuba, the procedural ``synth`` HDR chart;
   results.json says which).  Exposure times are log-spaced from "brightest pixel near
   DN 8" to "darkest 0.5 % of the lit pixels saturated", jittered off the geometric
   progression (+-0.4 of a step).  Recovery error of f^-1 over DN 16..4079, in % of the
   range; emulation with the recovered vs the true response.
2. **OpenCV** Debevec and Robertson calibrations on the same stacks.  They need 8-bit
   images: ``DN >> 4`` (12 -> 8 bit), the mono mosaic replicated to 3 channels, times in
   seconds.  Their curves (256 codes) are placed at the DN centres ``16 v + 7.5`` and
   interpolated; our method on the same 8-bit images is listed too.  Every curve is
   scale-aligned to the truth before the error is taken (f^-1 is defined up to scale).
3. **BorealHDR**: the response recovered from the borealhdr-preset stack against the
   real table ``pcalib_inside1.txt`` (the preset is a parametric fit of that table).
4. **In situ** on synthetic moving recordings (``synth.procedural.TranslatingChart``,
   walking speed, 1..32 ms sweeps) with each preset: recovered vs true f^-1 and the
   cross-bracket scores of the recovered, the true and a linear response.
5. **Real sample**: cross-bracket error (emulate each bracket from its sweep neighbours,
   compare 1..99 % quantiles, RMSE in % of 4094) of pcalib_inside1, a linear response and
   the in-situ responses (both cameras, and each camera scored on the other).

The package: :mod:`~validation.calibration_study.config` (presets, :data:`CONFIGS`),
:mod:`~validation.calibration_study.measure` (stacks, OpenCV curves, errors),
:mod:`~validation.calibration_study.study` (the parts and :func:`run_study`),
:mod:`~validation.calibration_study.report` (plots, ``report.md``),
:mod:`~validation.calibration_study.cli` (the command line).
"""

from __future__ import annotations

from validation.calibration_study.config import PRESETS, DN_RANGE, CONFIGS, SHOT_INTERVAL_S, BRACKETS_MS
from validation.calibration_study.measure import (
    study_radiance,
    electrons_per_ms,
    stack_exposures,
    capture_stack,
    opencv_curves,
    codes_to_dn_curve,
    curve_error,
    code_curve_error,
    emulation_check,
)
from validation.calibration_study.study import (
    static_part,
    borealhdr_check,
    insitu_synthetic,
    real_sample_part,
    run_study,
)
from validation.calibration_study.cli import main

__all__ = [
    "PRESETS",
    "DN_RANGE",
    "CONFIGS",
    "SHOT_INTERVAL_S",
    "BRACKETS_MS",
    "study_radiance",
    "electrons_per_ms",
    "stack_exposures",
    "capture_stack",
    "opencv_curves",
    "codes_to_dn_curve",
    "curve_error",
    "code_curve_error",
    "emulation_check",
    "static_part",
    "borealhdr_check",
    "insitu_synthetic",
    "real_sample_part",
    "run_study",
    "main",
]
