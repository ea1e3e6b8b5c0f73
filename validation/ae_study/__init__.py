"""Synthetic AE study: the paper's section V-D benchmarks on synthetic stereo walks.

Run::

    exposim validate ae-study -o OUT [--quick] [--cycles N] [--size WxH] [--spp S]
                                     [--scenes a,b,c] [--force]
    exposim validate ae-study -o OUT --redraw   # findings, report, figure from results.json
    python -m validation.ae_study OUT ...       # the same, OUT positional

The package: :mod:`~validation.ae_study.config` (scenes, methods, the paper's numbers,
:class:`StudyConfig`), :mod:`~validation.ae_study.summary` (per scene and pooled figures),
:mod:`~validation.ae_study.findings` (the paper's qualitative findings tested),
:mod:`~validation.ae_study.report` (``report.md`` with a verdict per result, the summary
figure), :mod:`~validation.ae_study.study` (running and redrawing),
:mod:`~validation.ae_study.cli` (the command line).

For each scene (default ``forest_winter``, ``forest_edge``, ``sun_glare``):

1. **Synthesise** a stereo bracketed walk (:func:`scenes.synthesize.synthesize`: Mitsuba
   radiance at every shot's own pose, the BorealHDR-fitted synthetic camera with noise,
   1..32 ms sweeps at 22 frames/s, ground-truth poses).  Seeds are explicit
   (:class:`StudyConfig`).  ``forest_edge`` gets its exit (``exit_x_m``) placed on the
   walk (at ``edge_exit_fraction`` of the path), so the sequence contains the passage from
   shade to sunlit snow whatever its length.
2. **Closed loop**: the seven AE methods on the recording
   (:func:`emulator.orchestration.runner.run_to_folder`, ``save="png16"``).
3. **Features** (paper Fig. 4) over all scenes' runs together
   (:func:`emulator.metrics.bench.bench_features`): SIFT grid uniformity, consecutive
   matches, success rate over sequences at ``tau`` = 5 and 100.  Because a handful of
   sequences gives a coarse rate (0, 1/3, 2/3, 1), the rate over fixed-length
   *segments* of ``segment_pairs`` consecutive pairs is reported beside it (labelled).
4. **Stereo VO** (paper Fig. 6) per scene (:func:`emulator.metrics.bench.bench_vo`,
   against the exact ground-truth poses, evo scale alignment); the RPE is computed for
   every run, failed ones included and marked (``rpe_on_failure``).  The headline RPE is
   the paper's "minimal error": the smallest median over the pair lengths (10..50 % of
   the path).

Writes ``OUT/results.json`` (configuration, per scene and per method figures, pooled
figures, the findings), ``OUT/report.md`` (a table per scene, the paper's numbers beside
them, and a paragraph on which of the paper's qualitative findings hold, generated from the
numbers), ``OUT/ae_study_summary.png`` and the benchmarks' own folders and figures
(``features/``, ``vo/<scene>/``, ``runs/<scene>/``, ``datasets/<scene>/``).  An existing
``OUT/results.json`` is never overwritten without ``force``.

Why the default size and VO ratio (measured on ``forest_winter``, 12 cycles, all seven
methods, 77 frame-to-frame VO steps; see ``VO_CONFIGURATION_NOTE``): at 192x120 and 8 spp
the path tracer's own noise is about 24 % per pixel (median, relative; 42 % in the
darker half; switching the sensor noise off changes nothing), so SIFT keypoints do not
repeat between the left and right images or between frames (21 % of keypoints re-found on two renders of the
same pose with different seeds, 66 % at 128 spp).  Samples spent on more pixels pay more
than samples spent on less noise: 256x160 at 8 spp failed 12 % of the steps with the
default ratio test and none with a ratio of 0.9, while 192x120 at 16 spp (more samples
per image) still failed 51 % and 16 %.
"""

from __future__ import annotations

from validation.ae_study.config import (
    CONFIGS,
    GRADIENT_METHODS,
    METHODS,
    PAPER,
    PAPER_NAMES,
    SCENES,
    VO_CONFIGURATION_NOTE,
    StudyConfig,
    StudyError,
    config_from_dict,
)
from validation.ae_study.findings import evaluate_findings, findings_paragraph
from validation.ae_study.report import plot_summary, report_markdown
from validation.ae_study.study import redraw, run_study
from validation.ae_study.summary import segment_success, summarise
from validation.ae_study.cli import main

__all__ = [
    "StudyConfig",
    "CONFIGS",
    "SCENES",
    "METHODS",
    "GRADIENT_METHODS",
    "PAPER",
    "VO_CONFIGURATION_NOTE",
    "StudyError",
    "run_study",
    "summarise",
    "evaluate_findings",
    "findings_paragraph",
    "report_markdown",
    "segment_success",
    "plot_summary",
    "redraw",
    "config_from_dict",
    "main",
]
