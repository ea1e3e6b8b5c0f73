"""Render study: speed against error of raw and denoised renders, and realism vs real frames.

Run::

    python -m validation.render_study OUT [--quick] [--scenes a,b] [--size WxH] [--spp 1,4,16]
                                          [--reference-spp N] [--texture-sizes 480x300,960x600]
                                          [--texture-spp S] [--texture-poses N] [--real PATH] [--force]

Per study scene (:data:`validation.common.STUDY_SCENES`), at the study size, for every spp
level, the raw path-traced estimate (``denoise="off"``) and the two denoised renders
(Open Image Denoise with albedo and normal, :mod:`scenes.denoise`: the default ``oidn`` and
the cheaper ``oidn-fast``) of one pose, each
against a raw reference of ``reference_spp`` samples (>= 1024 in the full study) at that
pose:

``time_s``
    Wall-clock seconds per frame, median over the renders after the first of each spp
    (the first compiles the kernels).  Raw: path tracing; denoised: path tracing plus the
    albedo/normal pass plus OIDN.
``rmse_pct``
    RMSE of noiseless synthetic-camera captures (BorealHDR response, 12 bit) against the
    reference's, in percent of the DN range (DESIGN.md), mean over ``error_exposures_ms``
    and the render seeds.
``bright_rel_err``, ``bright_halo``
    The hard case (sun disk, ice glints): over the brightest 0.1 % of the reference's
    pixels (luminance), the relative RMS luminance error; and in the ring of pixels within
    ``halo_px`` of them, mean luminance over the reference's minus 1 (positive: energy
    smeared out of the core).  The reference itself is the bound.
``repeat_seeds``
    SIFT keypoint repeatability (:func:`scenes.image_stats.keypoint_repeatability`,
    1.5 px) between two renders of the pose with different render seeds (same sensor
    noise draw, so the figure measures the renderer).
``repeat_walk``
    The same between consecutive frames of the scene's walk (one bracket cycle, 273 ms,
    apart): keypoints of frame A are moved into frame B through the exact depth and poses
    (Mitsuba's depth AOV), keypoints that leave the image or see the sky are dropped.
``flicker_pct``, ``flicker_ratio``
    Static camera: mean absolute change of the noiseless 8 ms capture between consecutive
    frames (renders with the frame seeds a static trajectory uses), percent of the DN
    range; and its ratio to the change the sensor's own noise makes between two frames of
    the reference (a ratio well below 1: the camera would not see the renderer's flicker).
``kp_per_mp``, ``median_gradient``
    Of the 8 ms frame with sensor noise (:func:`scenes.image_stats.synthetic_gray8`),
    beside the real frames' at the same size (``real``).

Texture targets (issue 13): for the texture scenes, denoised renders at ``texture_spp`` of
``texture_poses`` walk poses at every ``texture_sizes`` size: SIFT keypoints per megapixel,
median gradient and seed repeatability against the real BorealHDR frames of the 8 ms
bracket at the same size (both cameras; full-resolution grey then ``INTER_AREA``).

Speed-up: for every denoised spp, the time the raw estimate needs for the same error,
interpolated on the raw curve in log-log (extrapolated beyond its last two points when the
denoised error is below every raw one: flagged), over the denoised time.

Writes ``OUT/results.json``, ``OUT/report.md`` (the table) and ``OUT/time_vs_error.png``;
refuses to overwrite an earlier ``results.json`` without ``force``.

The package: :mod:`~validation.render_study.config` (:class:`RenderStudyConfig`, :data:`CONFIGS`,
the targets), :mod:`~validation.render_study.measure` (the measures above),
:mod:`~validation.render_study.study` (running), :mod:`~validation.render_study.report` (the
table and the figure), :mod:`~validation.render_study.cli` (the command line).
"""

from __future__ import annotations

from validation.render_study.config import (
    DEFAULT_REAL_SEQUENCE,
    TARGET_TOLERANCE,
    TARGET_REPEATABILITY,
    RenderStudyConfig,
    CONFIGS,
)
from validation.render_study.measure import bright_errors, walk_repeatability, speedups
from validation.render_study.study import run_render_study, total_steps
from validation.render_study.report import render_study_table
from validation.render_study.cli import add_arguments, config_from_args, run_from_args, print_summary, main

__all__ = [
    "DEFAULT_REAL_SEQUENCE",
    "TARGET_TOLERANCE",
    "TARGET_REPEATABILITY",
    "RenderStudyConfig",
    "CONFIGS",
    "bright_errors",
    "walk_repeatability",
    "speedups",
    "run_render_study",
    "total_steps",
    "render_study_table",
    "add_arguments",
    "config_from_args",
    "run_from_args",
    "print_summary",
    "main",
]
