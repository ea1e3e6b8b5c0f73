"""One copy of each helper that had disagreeing copies: the median of finite values and the number
formatter (``emulator.cells``), the pose check (``synth.pose``, also ``scenes.camera.check_pose``) and the
sharpness measure (``validation.blur.measure.sharpness``, also used by ``scripts/blur_sample_checks.py``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import scenes.camera
from emulator.cells import DASH, MISSING, format_number, median_finite
from emulator.report.verdicts import DASH_NOTE, dash_cell
from synth.errors import PoseError
from synth.pose import check_pose
from validation.blur.measure import sharpness


def test_median_finite_leaves_out_none_nan_and_infinities():
    assert median_finite([5, None, float("nan"), 1, float("inf"), -float("inf"), 3]) == 3.0
    assert median_finite(np.array([1.0, 2.0, np.nan, 4.0])) == 2.0
    assert median_finite(iter([2, 7])) == 4.5


def test_median_finite_is_none_with_no_finite_value():
    assert median_finite([]) is None
    assert median_finite([None, float("nan"), float("inf")]) is None


def test_format_number_spells_a_missing_value_one_way():
    assert MISSING == "n/a"
    assert format_number(None) == format_number(None, "+.1%") == "n/a"
    assert format_number(0.0123456) == "0.0123"
    assert format_number(3, ".2f") == "3.00"
    assert format_number(np.float32(0.25), "+.1%") == "+25.0%"
    assert format_number(float("nan")) == "nan"
    assert (format_number(True), format_number(False)) == ("yes", "no")
    assert format_number("agrees") == "agrees"


def test_the_reports_that_print_a_dash_use_the_one_formatter():
    """A missing value prints as ``missing`` and nothing else changes: the dash tables (run, bench, VO reports,
    whose notes explain a "-" cell) go through format_number too."""
    assert DASH == "-" and '"-" cell' in DASH_NOTE
    assert format_number(None, missing=DASH) == format_number(None, "+.1%", missing=DASH) == "-"
    assert format_number(2.345, ".2f", missing=DASH) == format_number(2.345, ".2f") == "2.35"
    assert format_number(np.int64(7), "d", missing=DASH) == "7"  # an integer spec: the bench's matches
    assert format_number(7, "3d") == "  7"
    assert (dash_cell(None), dash_cell(12.25), dash_cell(5, "d")) == ("-", "12.2", "5")
    for value, spec in [(None, ".3g"), (0.0123456, ".3g"), (np.float32(1.5), ".1f"), (3, ".0f"), (1e-7, ".3g")]:
        assert dash_cell(value, spec) == format_number(value, spec, missing="-")


def test_a_run_report_prints_a_missing_figure_as_a_dash():
    from emulator.report.run import run_markdown

    method = {"mode": "paper", "cycles": 0, "mean_exposure_ms": None, "median_exposure_ms": None,
              "min_exposure_ms": None, "max_exposure_ms": None, "mean_saturated_fraction": None,
              "mean_valid_fraction": 0.5, "non_finite_proposals": 0, "method_ms_per_frame": 1.25}
    text = run_markdown({"sequence": "/x/seq", "status": "complete"}, {"methods": {"zhang": method}})
    row = next(line for line in text.splitlines() if line.startswith("| zhang |"))
    assert row == "| zhang | paper | 0 | - | - | - | - | - | 50.00 | 0 | 1.2 |"


def test_one_pose_check_for_synth_and_scenes():
    assert scenes.camera.check_pose is check_pose
    pose = np.eye(4)
    pose[:3, 3] = (1.0, 2.0, 3.0)
    out = check_pose(pose.tolist())
    assert out.dtype == np.float64 and np.array_equal(out, pose)


@pytest.mark.parametrize("pose, problem", [
    (np.eye(3), r"frame 4: pose must be a finite 4x4 matrix, got shape \(3, 3\)$"),
    (np.full((4, 4), np.nan), "frame 4: pose must be a finite 4x4 matrix, got shape \\(4, 4\\) with a value that is not finite"),
    ([[1, 0], [0, 1, 0]], "frame 4: pose must be a finite 4x4 matrix, got list that is not a numeric array"),
    ("eye", "frame 4: pose must be a finite 4x4 matrix, got str that is not a numeric array"),
    (np.diag([1.0, 1.0, 1.0, 2.0]), r"frame 4: pose bottom row must be \(0, 0, 0, 1\), got \[0.0, 0.0, 0.0, 2.0\]"),
    (np.diag([1.0, 1.0, -1.0, 1.0]), "frame 4: the pose's 3x3 block is not a rotation"),
])
def test_a_bad_pose_is_one_error_naming_the_problem(pose, problem):
    with pytest.raises(PoseError, match=problem):
        check_pose(pose, "frame 4")


def test_sharpness_on_a_constructed_mosaic():
    """Green sites of an RGGB mosaic averaged into one plane (rows of 10, 20, 30, ...): every gradient is 10,
    so p95 of the gradient over the median level (45 of 10..80) is 10 / 45."""
    raw = np.zeros((16, 16), dtype=np.uint16)
    level = 10.0 * (1 + np.arange(8))[:, None] * np.ones((1, 8))
    raw[0::2, 1::2] = level
    raw[1::2, 0::2] = level
    assert math.isclose(sharpness(raw), 10.0 / 45.0, rel_tol=1e-12)
    raw[0::2, 0::2] = 4000  # red and blue sites do not count
    assert math.isclose(sharpness(raw), 10.0 / 45.0, rel_tol=1e-12)
    assert math.isnan(sharpness(np.zeros((8, 8), dtype=np.uint16)))
