"""A clip too short for the methods to settle: :mod:`emulator.core.settling` and the run report's words."""

from __future__ import annotations

import numpy as np
import pytest

from emulator.report.run import _trending_note, per_recorder_cycle
from emulator.core.settling import still_trending, trending_methods


def test_a_method_still_climbing_at_the_end_is_trending():
    t = [4.0, 1.2, 6.8, 10.0, 14.0, 20.0, 27.0]  # rising over the last 3 steps: 10 -> 27 ms
    assert still_trending(t) == {"direction": "rising", "change_fraction": pytest.approx(1.7), "steps": 3}
    assert still_trending([30.0, 20.0, 15.0, 10.0])["direction"] == "falling"


@pytest.mark.parametrize("t", [
    [4.0, 8.0, 8.0, 8.0, 8.0],          # settled
    [4.0, 8.0, 7.9, 8.1, 8.0],          # dithering round a point
    [8.0, 8.1, 8.15, 8.2],              # one way, but by 2.5 % only
    [4.0, 8.0, 16.0],                   # too short to tell (3 steps need 4 values)
    [np.nan, np.inf, 1.0, 2.0],         # non-finite values left out: too short
])
def test_settled_or_too_short_is_not_trending(t):
    assert still_trending(t) is None


def test_the_report_names_the_methods_that_had_not_settled():
    trending = trending_methods({"kim": [1, 2, 4, 8], "fixed": [4, 4, 4, 4]})
    assert list(trending) == ["kim"] and trending["kim"]["change_fraction"] == pytest.approx(7.0)
    note = " ".join(_trending_note({"methods": {"kim": {}, "fixed": {}}, "still_trending": trending}, "cycles"))
    assert "Too short to settle:** 1 of 2 method(s)" in note and "kim (rising 700 %)" in note
    assert _trending_note({"methods": {}}, "cycles") == []


def test_native_tables_are_judged_per_recorder_cycle():
    table = {"target_ms": np.array([1.0, 2.0, 3.0, 4.0]), "benchmarked": np.array([1, 0, 1, 0])}
    assert per_recorder_cycle(table)["target_ms"].tolist() == [1.0, 3.0]
    cycle = {"target_ms": np.array([1.0, 2.0])}
    assert per_recorder_cycle(cycle) is cycle
