"""Emulation accuracy on exact synthetic ground truth (paper section V-B, Fig. 3).

For each static scene and camera: capture the six brackets once (noisy, as a real sweep,
and noiseless), and at each of N ground-truth exposures (log-spaced 0.02..50 ms) capture
``repeats`` noisy images plus the exact noiseless image.  Every bracket is emulated to
every ground-truth exposure; the bracket selector's choice indexes those results.

Error figures (RMSE in percent of the DN range, :mod:`validation.common`):

``raw``
    noisy emulation against one noisy ground-truth capture (repeat 0), as on a real camera;
``pair``
    the camera's own noise as the paper measures it: the RMSE between consecutive
    captures at the same exposure, ``sqrt(2) sigma``, with ``sigma^2`` the per-pixel
    variance estimated from the consecutive pairs of the repeats
    (:func:`validation.common.pair_noise_map`) averaged over the same pixels as the RMSE;
``sub`` (the headline)
    ``sqrt(max(raw^2 - sigma^2, 0))``: the ground truth's own noise removed.  It is
    independent of the emulated image, so squared errors add and the subtraction is done
    on squares; the result estimates the RMSE of the emulated image against the
    noise-free image (``exact`` checks the estimator).  The bracket's noise, scaled
    through the ratio, stays in: it is part of what the emulator outputs;
``sub_pair``
    ``sqrt(max(raw^2 - pair^2, 0))``: the paper's "error between consecutive images"
    subtracted (in quadrature): the error beyond what a second real capture would show.
    Emulating down from a longer bracket gives an image less noisy than a capture, so
    this clamps to 0 at most exposures and cannot resolve errors below the camera noise;
``sub_linear``
    the paper's words taken literally, ``max(raw - pair, 0)``;
``exact``
    noisy emulation against the exact noiseless ground truth (what ``sub`` estimates);
``clean``
    noiseless mode: noiseless bracket against noiseless ground truth, which isolates the
    emulation error (quantisation and clipping) from sensor noise; it is checked per pixel
    against :func:`validation.common.quantisation_bound`.

Each is computed over the validity mask of the emulated image (``*_valid``), over all
pixels (``*_all``) and over the invalid pixels (``*_invalid``), with the valid fraction.

The package: :mod:`~validation.emulation.config` (:class:`EmulationConfig`),
:mod:`~validation.emulation.measure` (the sweep, bracket choice, hard cases),
:mod:`~validation.emulation.study` (:func:`run_emulation`),
:mod:`~validation.emulation.report` (verdicts, figures, ``report.md``),
:mod:`~validation.emulation.cli` (``python -m validation.emulation OUT``, the same as
``exposim validate emulation -o OUT``).
"""

from __future__ import annotations

from validation.emulation.config import METRICS, BOUND_TOL_DN, HIST_BINS, EmulationConfig, HARD_EXPOSURES_MS
from validation.emulation.measure import SweepResult, sweep_static, choose_brackets, hard_cases
from validation.emulation.study import run_emulation
from validation.emulation.report import emulation_verdict
from validation.emulation.cli import main

__all__ = [
    "METRICS",
    "BOUND_TOL_DN",
    "HIST_BINS",
    "EmulationConfig",
    "HARD_EXPOSURES_MS",
    "SweepResult",
    "sweep_static",
    "choose_brackets",
    "hard_cases",
    "run_emulation",
    "emulation_verdict",
    "main",
]
