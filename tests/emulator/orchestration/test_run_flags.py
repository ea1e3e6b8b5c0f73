"""Partial cycles and large upward ratios are flagged in a run's results and report; ``--skip-partial``.

The recording is the static linear one of :mod:`test_playback`, with brackets left out: cycle 0
lacks the right camera's 1 ms shot, cycle 4 holds only the 1 ms shot of each camera.  A clamp
of ``LOW = HIGH`` pins every target, so each ratio is known exactly: at 12 ms, cycle 4 is
emulated from 1 ms (ratio 12, above the bound 8); the complete cycles take 8 ms (16 ms
saturates more than 1 % of the scene, whose values reach 200 * 16 * 1.5 = 4800 DN), ratio 1.5.
"""

from __future__ import annotations

import json

import pytest

from emulator.commands.cli import main
from emulator.orchestration.datasetrun import DATASET_FILE, run_dataset
from emulator.core.emulate import UPWARD_RATIO_FLAG
from emulator.io.runfolder import read_csv_rows
from emulator.playback import RunConfig
from emulator.orchestration.runner import run_to_folder
from tests.emulator.playback.test_playback import write_static_sequence

PARTIAL = [{"cycle": 0, "missing": {"right": [1.0]}},
           {"cycle": 4, "missing": {"left": [2.0, 4.0, 8.0, 16.0, 32.0], "right": [2.0, 4.0, 8.0, 16.0, 32.0]}}]


def _partial_seq(root):
    seq, _ = write_static_sequence(root, n_cycles=6, shape=(32, 48), drop={(0, "right", 1.0)},
                                   only={4: {"left": (1.0,), "right": (1.0,)}})
    return seq


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    return _partial_seq(tmp_path_factory.mktemp("flags") / "seq")


def _run(seq, out, target_ms, *extra):
    t = str(target_ms)
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(out), "--initial-ms", t,
                 "--range-ms", t, t, "--no-progress", *extra]) == 0
    return json.loads((out / "results.json").read_text()), (out / "report.md").read_text()


def _cycles(out, method="classical-50"):
    return [int(r[0]) for r in read_csv_rows(out / method / "exposures.csv")]


def test_the_bound_is_eight():
    assert UPWARD_RATIO_FLAG == 8.0


def test_partial_cycles_and_a_ratio_above_the_bound_are_flagged(seq, tmp_path, capsys):
    results, report = _run(seq, tmp_path / "r", 12.0)
    out = capsys.readouterr().out
    flags = results["flags"]
    assert flags["partial_cycles"] == PARTIAL and flags["partial_cycles_skipped"] == 0
    assert flags["upward_ratio_bound"] == 8.0
    assert flags["methods"]["classical-50"] == {"partial_cycles_used": 2, "cycles_above_ratio_bound": 1,
                                                "worst_upward_ratio": 12.0}
    assert _cycles(tmp_path / "r") == [0, 1, 2, 3, 4, 5]  # default: partial cycles are used
    ratios = {int(r[0]): float(r[4]) for r in read_csv_rows(tmp_path / "r" / "classical-50" / "exposures.csv")}
    assert ratios == {0: 1.5, 1: 1.5, 2: 1.5, 3: 1.5, 4: 12.0, 5: 1.5}
    assert "cycles 6/6 (2 partial; 1 method(s) emulated up by more than 8x: see Flags)" in report
    assert "- cycle 4: left missing 2, 4, 8, 16, 32 ms; right missing 2, 4, 8, 16, 32 ms" in report
    assert "- cycle 0: right missing 1 ms" in report
    assert "| classical-50 | 2 | 1 | 12 |" in report
    html = (tmp_path / "r" / "report.html").read_text()
    assert "cycle 4: left missing 2, 4, 8, 16, 32 ms" in html
    assert "partial     2 cycle(s) missing brackets (0, 4), used" in out
    assert "classical-50: 1 cycle(s), largest 12" in out


def test_a_ratio_of_exactly_the_bound_is_not_flagged(seq, tmp_path):
    results, report = _run(seq, tmp_path / "r", 8.0)
    m = results["flags"]["methods"]["classical-50"]
    assert m["cycles_above_ratio_bound"] == 0 and m["worst_upward_ratio"] == 8.0  # 8 ms from 1 ms in cycle 4
    assert "emulated up by more than" not in report.splitlines()[3]


def test_a_complete_recording_has_no_flags(tmp_path):
    seq, _ = write_static_sequence(tmp_path / "full", n_cycles=3, shape=(32, 48))
    results, report = _run(seq, tmp_path / "r", 12.0)
    assert "flags" not in results and "Flags" not in report
    assert "partial_cycles" not in json.loads((tmp_path / "r" / "run.json").read_text())
    assert "skip_partial" not in json.loads((tmp_path / "r" / "run.json").read_text())


def test_skip_partial_leaves_out_cycles_missing_a_bracket(seq, tmp_path, capsys):
    results, report = _run(seq, tmp_path / "r", 12.0, "--skip-partial")
    out = capsys.readouterr().out
    run_json = json.loads((tmp_path / "r" / "run.json").read_text())
    assert run_json["skip_partial"] is True and "--skip-partial" in run_json["command"]
    assert _cycles(tmp_path / "r") == [1, 2, 3, 5]
    assert [s["cycle"] for s in results["skipped_cycles"]] == [0, 4]
    assert results["skipped_cycles"][0]["missing"] == {"left": [], "right": [1.0]}
    flags = results["flags"]
    assert flags["partial_cycles_skipped"] == 2
    assert flags["methods"]["classical-50"] == {"partial_cycles_used": 0, "cycles_above_ratio_bound": 0,
                                                "worst_upward_ratio": 1.5}
    assert "Skipped cycles: 2" in report
    assert "- cycle 4: partial cycle left out (--skip-partial): left missing 2, 4, 8, 16, 32 ms" in report
    assert "cycles      6/6 (2 skipped)" in out and "2 left out (--skip-partial)" in out


def test_resume_keeps_skip_partial_and_refuses_a_change(seq, tmp_path, capsys):
    full = tmp_path / "full"
    _run(seq, full, 12.0, "--skip-partial")
    out = tmp_path / "r"

    def stop(done, total):
        if done == 3:
            raise KeyboardInterrupt

    cfg = RunConfig(initial_ms=12.0, range_ms=(12.0, 12.0), skip_partial=True)
    with pytest.raises(KeyboardInterrupt):
        run_to_folder(seq, ["classical-50"], out, cfg, progress=stop)
    assert main(["run", str(seq), "-o", str(out), "--resume", "--no-progress"]) == 0  # recorded setting wins
    assert _cycles(out) == [1, 2, 3, 5]
    assert (out / "classical-50" / "exposures.csv").read_bytes() == \
        (full / "classical-50" / "exposures.csv").read_bytes()
    plain = tmp_path / "plain"
    with pytest.raises(KeyboardInterrupt):
        run_to_folder(seq, ["classical-50"], plain, cfg.replace(skip_partial=False), progress=stop)
    assert main(["run", str(seq), "-o", str(plain), "--resume", "--skip-partial", "--no-progress"]) == 1
    assert "different configuration (skip_partial)" in capsys.readouterr().err


def test_config_refuses_a_non_boolean_and_reads_old_folders():
    from emulator.errors import PlaybackError

    with pytest.raises(PlaybackError, match="skip_partial must be true or false"):
        RunConfig(skip_partial="yes")
    assert RunConfig.from_json({}).skip_partial is False
    assert RunConfig.from_json(RunConfig(skip_partial=True).to_json()).skip_partial is True


def test_dataset_run_respects_skip_partial(tmp_path):
    root = tmp_path / "root"
    _partial_seq(root / "a")
    summary = run_dataset(root, tmp_path / "d", RunConfig(initial_ms=12.0, range_ms=(12.0, 12.0), skip_partial=True),
                          methods="classical-50")
    assert not summary["errors"]
    assert json.loads((tmp_path / "d" / DATASET_FILE).read_text())["config"]["skip_partial"] is True
    unit = tmp_path / "d" / "a" / "classical-50"  # one unit per (sequence, method group)
    assert _cycles(unit) == [1, 2, 3, 5]
    assert json.loads((unit / "results.json").read_text())["flags"]["partial_cycles_skipped"] == 2
    with pytest.raises(Exception, match="different configuration"):
        run_dataset(root, tmp_path / "d", RunConfig(initial_ms=12.0, range_ms=(12.0, 12.0)),
                    methods="classical-50", resume=True)
