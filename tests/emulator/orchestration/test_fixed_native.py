"""``fixed`` at native rate: one exposure from frame ``n_adjustments * (latency + 1)`` on, at latency 0, 1 and 3.

Issue 46: with ``--latency-frames 1`` two proposals were in flight when ``fixed`` froze, and returning the
input exposure re-queued them: a period-2 cycle (6.106 / 7.732 ms on the shared sample) to the end.
"""

from __future__ import annotations

import csv
import warnings

import numpy as np
import pytest

from emulator.autoexposure import make_method
from emulator.autoexposure.classical import Fixed
from emulator.autoexposure.methodset import latency_options
from emulator.orchestration.runner import run_to_folder
from tests.conftest import static_chart_recording  # noqa: E402

LATENCIES = (0, 1, 3)


def _exposures(out) -> list[float]:
    with open(out / "fixed" / "exposures.csv", newline="") as fh:
        return [float(r["target_ms"]) for r in csv.DictReader(fh)]


def _native_fixed(seq, out, latency: int, **kw) -> list[float]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run_to_folder(seq, "fixed,classical-50", out, rate="native", latency_frames=latency, **kw)
    return _exposures(out)


def _check_frozen(ms: list[float], latency: int) -> None:
    frozen_from = Fixed().n_adjustments * (latency + 1)
    assert len(ms) > frozen_from + 2
    assert len(set(ms[frozen_from:])) == 1, ms  # one exposure to the end: no cycle between the last proposals
    assert len(set(ms[:frozen_from + 1])) > 1, ms  # it did adjust before freezing


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A static stereo chart, 24 shots, no IMU: the initial exposure is far from classical-50's target."""
    return static_chart_recording(tmp_path_factory.mktemp("fixnat") / "static", 40, 24, dynamic_range_db=50.0,
                                  n_shots=24, noise=True)


@pytest.mark.parametrize("latency", LATENCIES)
def test_fixed_freezes_one_exposure_at_native_rate(recording, tmp_path, latency):
    ms = _native_fixed(recording, tmp_path / "run", latency, initial_ms=1.0)
    _check_frozen(ms, latency)


def test_fixed_method_holds_its_last_adjustment_with_proposals_in_flight():
    raw = np.full((8, 8), 400, dtype=np.uint16)  # dark: classical-50 lengthens t
    m = Fixed(mode="paper", range_ms=None, latency_frames=1)
    # adjusting calls see the previous adjustment applied (calls 0, 2, 4); the others return it
    out = [m.next_exposure(raw, t) for t in (1.0, 1.0, 4.296, 4.296, 7.592, 7.592, 10.888, 10.888)]
    step = 0.002 * (2048 - 400)
    assert out[0] == pytest.approx(1.0 + step) and out[1] == out[0]
    assert out[2] == pytest.approx(4.296 + step) and out[3] == out[2]
    assert out[4] == pytest.approx(7.592 + step)
    assert out[5:] == [out[4]] * 3  # frozen: the input exposure no longer matters
    m.reset()
    assert m.next_exposure(raw, 1.0) == pytest.approx(1.0 + step)


def test_latency_zero_keeps_the_cycle_rate_method():
    assert latency_options({"zhang": {"a": 1}}, 0) == {"zhang": {"a": 1}}
    assert latency_options(None, 2) == {"fixed": {"latency_frames": 2}}
    assert latency_options({"fixed": {"latency_frames": 0}}, 2) == {"fixed": {"latency_frames": 0}}  # the user's wins
    assert make_method("fixed").config() == {"name": "fixed", "mode": "paper", "range_ms": [0.02, 50.0],
                                             "n_auto_frames": 3}
    with pytest.raises(Exception, match="latency_frames"):
        Fixed(latency_frames=-1)


@pytest.mark.slow
@pytest.mark.parametrize("latency", LATENCIES)
def test_fixed_freezes_one_exposure_on_the_shared_sample(sample_seq, tmp_path, latency):
    ms = _native_fixed(sample_seq, tmp_path / "run", latency, workers="inline")
    _check_frozen(ms, latency)


def test_the_native_report_counts_frames_and_says_where_fixed_differs(recording, tmp_path):
    _native_fixed(recording, tmp_path / "run", 1, initial_ms=1.0)
    report = (tmp_path / "run" / "report.md").read_text()
    assert "| method | mode | frames |" in report and "over the run's frames" in report
    assert "over the run's cycles" not in report
    assert "frames from partial cycles" in report or "Flags" not in report
    assert "on this run the two differ" in report and "identical to classical-50" not in report


def test_a_native_run_in_a_log_prints_its_frames(recording, tmp_path, capsys):
    """Issue 46: off a terminal ``run --rate native`` prints stage lines (here stderr is captured, not a tty)."""
    from emulator.commands.cli import main

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["run", str(recording), "--rate", "native", "--methods", "fixed", "-o", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err
    assert "exposim run [" in err and ": frames 1/24" in err and ": frames 24/24" in err
    assert _exposures(tmp_path / "r")[6:] == [_exposures(tmp_path / "r")[6]] * 18  # frozen from frame 3 x 2
