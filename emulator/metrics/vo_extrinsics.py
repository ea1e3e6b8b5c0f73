"""The stereo extrinsics check of the VO benchmark: the given calibration's epipolar residual on a few
stereo pairs of a run and, where it is too large (or when asked), the rig's rotation re-estimated from
left-right matches.  :func:`decide_extrinsics` is what :func:`emulator.metrics.vo_bench.bench_vo` calls;
:func:`check_extrinsics` is the same for ``exposim export``.
"""

from __future__ import annotations

import numpy as np

from emulator.errors import CalibrationError, MetricsError
from emulator.io.runfolder import RunFolder
from emulator.metrics.features import load_gray8
from emulator.metrics.stereo import epipolar_residual_px, estimate_stereo_extrinsics, stereo_matches
from emulator.metrics.vo import VOParameters

__all__ = [
    "REFINE_PAIRS",
    "REFINE_THRESHOLD_FRACTION",
    "check_extrinsics",
    "decide_extrinsics",
]

#: Stereo pairs (spread over the first method's frames) used to measure the calibration's
#: epipolar residual and, where needed, to re-estimate the extrinsics.
REFINE_PAIRS = 2
#: ``refine_extrinsics="auto"`` refines when the median epipolar residual of left-right
#: matches under the given calibration exceeds this fraction of the VO's row tolerance
#: (``VOParameters.max_row_diff_px``): beyond it, most true matches fall outside the
#: stereo row check and the VO loses its depth points.
REFINE_THRESHOLD_FRACTION = 0.5


def check_extrinsics(calib, frames, run: RunFolder, mode="auto", parameters: VOParameters | None = None):
    """``bench vo``'s extrinsics check and refinement (the same code): ``(calibration, record)``.

    ``frames``: a method's run frames (stereo pairs); ``mode``: ``"auto"``, 0 or a number of
    pairs.  ``record`` holds ``epipolar_residual_px``, ``refined``, ``reason`` and, when
    refined, ``estimate`` (with ``epipolar_residual_after_px``); ``limitations`` when refinement
    was needed and failed.
    """
    limitations: list[str] = []
    calib, record = decide_extrinsics(calib, frames, run, mode, parameters or VOParameters(), limitations)
    if limitations:
        record["limitations"] = limitations
    return calib, record


def decide_extrinsics(calib, frames, run: RunFolder, mode, parameters: VOParameters, limitations: list[str]):
    """The calibration to rectify with, and the record of the extrinsics decision (``mode``: ``"auto"``, 0
    or a number of pairs); a refinement that was needed and failed adds its sentence to ``limitations``."""
    if mode in (0, "0", "never", None):
        return calib, {"mode": "never", "refined": False, "reason": "refinement disabled (--refine-extrinsics 0)"}
    auto = mode == "auto"
    if not auto:
        try:
            n_pairs = int(mode)
        except (TypeError, ValueError):
            raise MetricsError(f"refine_extrinsics must be 'auto', 0 or a number of stereo pairs, got {mode!r}") from None
        if n_pairs < 0:
            raise MetricsError(f"refine_extrinsics must be 'auto', 0 or a positive number of pairs, got {n_pairs}")
    else:
        n_pairs = REFINE_PAIRS
    picks = np.unique(np.linspace(0, len(frames) - 1, min(n_pairs, len(frames))).round().astype(int))
    pairs = (
        (load_gray8(frames[i].left, white_level=run.white_level, black_level=run.black_level),
         load_gray8(frames[i].right, white_level=run.white_level, black_level=run.black_level))
        for i in picks
    )
    matches = stereo_matches(calib, pairs, seed=parameters.seed)
    residual = epipolar_residual_px(calib, matches)
    threshold = REFINE_THRESHOLD_FRACTION * parameters.max_row_diff_px
    record = {
        "mode": "auto" if auto else f"always ({n_pairs} pairs)",
        "n_pairs": int(len(picks)),
        "n_matches": matches.n_matches,
        "epipolar_residual_px": None if not np.isfinite(residual) else round(residual, 4),
        "threshold_px": threshold,
        "criterion": (f"median epipolar distance of left-right SIFT matches (ratio 0.7) of {len(picks)} stereo pair(s) "
                      f"under the given calibration > {threshold:g} px ({REFINE_THRESHOLD_FRACTION:g} x the VO's row "
                      f"tolerance of {parameters.max_row_diff_px:g} px)"),
        "refined": False,
    }
    if auto and not (np.isfinite(residual) and residual > threshold):
        record["reason"] = ("the given calibration fits the images" if np.isfinite(residual)
                            else "no left-right match to measure the residual; calibration used as given")
        return calib, record
    try:
        est = estimate_stereo_extrinsics(calib, matches, seed=parameters.seed)
    except CalibrationError as exc:
        if not auto:
            raise
        record["reason"] = f"refinement needed but failed ({exc}); calibration used as given"
        limitations.append(f"Stereo extrinsics: the calibration leaves a {residual:.1f} px epipolar residual and "
                           f"could not be refined ({exc}); stereo depth will be poor.")
        return calib, record
    record.update(refined=True, estimate=est.to_dict(),
                  reason=(f"re-estimated, as the residual exceeds {threshold:g} px" if auto
                          else f"re-estimated, as asked (--refine-extrinsics {n_pairs})"))
    return calib.with_extrinsics(est.R, est.T), record
