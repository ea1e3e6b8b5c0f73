"""``exposim demo --quick`` runs the whole chain: synth -> emulation check -> 7 AE methods -> features/VO."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from emulator.commands.cli import main
from emulator.errors import OutputExistsError
from validation.demo import demo_config, demo_dataset, demo_dataset_key, new_output_dir, run_demo

pytestmark = [pytest.mark.render, pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[2]


def _tree(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*") if p.is_file()}


def _demo_in_a_log(tmp_path, *args) -> subprocess.CompletedProcess:
    """``exposim demo --quick`` as in a batch log: stdout and stderr are pipes, not a terminal."""
    env = {**os.environ, "EXPOSIM_DENOISE": "off", "EXPOSIM_CACHE": str(tmp_path / "cache"),
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    got = subprocess.run([sys.executable, "-m", "emulator.commands.cli", "demo", "--quick", *args], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=600)
    assert got.returncode == 0, got.stderr
    return got


def test_quick_demo_end_to_end(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("EXPOSIM_DENOISE", "off")  # not a rendering test: raw renders keep it fast
    cache = tmp_path / "cache"
    monkeypatch.setenv("EXPOSIM_CACHE", str(cache))
    out = tmp_path / "demo"
    # in a log: one line per stage on stderr as it starts (no bar), and a short summary on stdout
    got = _demo_in_a_log(tmp_path, "-o", str(out))
    stages = ["1/4 synthesise forest_winter", "2/4 emulation against ground truth", "3/4 closed loop, 7 methods",
              "4/4 features and stereo VO"]
    lines = got.stderr.splitlines()
    assert [line.split("]: ", 1)[1] for line in lines] == stages, got.stderr
    assert all(re.fullmatch(r"exposim demo \[\d+ s\]: .+", line) for line in lines) and "\r" not in got.stderr
    printed = got.stdout.splitlines()
    assert 4 <= len(printed) <= 8 and "| method |" not in got.stdout and "# exposim demo" not in got.stdout
    assert printed[0].startswith("exposim demo: forest_winter, 4 bracket cycles at 96x60 px, 7 AE methods")
    assert printed[-1].startswith("exposim demo: done in ") and f"report: {out / 'report.html'} " in printed[-1]
    results = json.loads((out / "results.json").read_text())
    emu = results["emulation"]
    assert f"median RMSE {emu['median_rmse_percent']:.2f} % of the range, max {emu['max_rmse_percent']:.2f} %" in got.stdout
    assert "synthesised now" in got.stdout
    report = (out / "report.md").read_text()
    assert "# exposim demo" in report and "one render per bracket sweep (6 shots) and camera" in report
    assert "not denoised" in report  # EXPOSIM_DENOISE=off reaches the recording, and the report says so
    # the recording lives in the render cache, keyed by its configuration; the demo folder
    # holds the run results only (issue 11: every demo left another full copy)
    dataset = Path(results["dataset"])
    assert dataset == cache / "datasets" / f"demo-{demo_dataset_key(demo_config(quick=True))}"
    assert results["dataset_reused"] is False and (dataset / "exposim.json").is_file()
    assert not (out / "dataset").exists() and not any(p.name == "exposim.json" for p in out.rglob("*"))
    assert (out / "report.md").is_file() and (out / "run" / "exposure.png").is_file()
    assert set(results["run"]["methods"]) == {
        "fixed", "classical-30", "classical-50", "classical-70", "shim", "zhang", "kim"
    }
    emu = results["emulation"]
    # emulated vs noiseless ground truth at the same instant: the source bracket's own
    # sensor noise (a few tenths of a percent) plus quantisation; far below a wrong response
    assert 0 < emu["median_rmse_percent"] < 1.5
    assert emu["max_rmse_percent"] < 3.0
    assert (out / "features" / "results.json").is_file() and (out / "vo" / "results.json").is_file()
    with pytest.raises(OutputExistsError):
        run_demo(out, quick=True)
    # a second demo reads the same recording (not a byte of it rewritten) into a new folder
    before = _tree(dataset)
    again = tmp_path / "demo-again"
    assert main(["demo", "--quick", "-q", "-o", str(again)]) == 0
    assert f"recording: {dataset} (reused from an earlier demo)" in capsys.readouterr().out
    second = json.loads((again / "results.json").read_text())
    assert second["dataset"] == str(dataset) and second["dataset_reused"] is True
    assert second["emulation"] == emu  # same recording, same figures
    assert _tree(dataset) == before and (out / "results.json").read_text() == json.dumps(results, indent=1) + "\n"
    # the new folder holds run results only, none of the recording's parts
    parts = {p.name for p in dataset.iterdir()}
    assert {"camera_left", "camera_right", "ground_truth", "imu"} <= parts
    assert not any(p.name in parts for p in again.rglob("*"))


def test_damaged_cached_recording_is_written_again_and_user_files_are_kept(tmp_path, monkeypatch):
    monkeypatch.setenv("EXPOSIM_CACHE", str(tmp_path / "cache"))
    cfg = dict(demo_config(quick=True), n_cycles=1)
    dataset, reused = demo_dataset(cfg)
    assert not reused
    assert demo_dataset(cfg) == (dataset, True)
    png = sorted((dataset / "camera_left").rglob("*.png"))[0]
    good = png.read_bytes()
    png.unlink()  # damaged: written again, not reused
    assert demo_dataset(cfg) == (dataset, False) and png.read_bytes() == good
    (dataset / "notes.txt").write_text("mine")
    png.unlink()
    with pytest.raises(OutputExistsError, match="notes.txt"):
        demo_dataset(cfg)
    assert (dataset / "notes.txt").read_text() == "mine"


def test_default_output_never_overwrites(tmp_path):
    base = tmp_path / "exposim-demo"
    (tmp_path / "exposim-demo-1").mkdir()
    assert new_output_dir(base) == tmp_path / "exposim-demo-2"


def test_json_output_is_strict_json_in_a_log_and_quiet_prints_no_progress(tmp_path):
    first = _demo_in_a_log(tmp_path, "--json", "-o", str(tmp_path / "a"))
    assert json.loads(first.stdout) == json.loads((tmp_path / "a" / "results.json").read_text())
    assert len(first.stderr.splitlines()) == 4  # the stage lines stay on stderr
    quiet = _demo_in_a_log(tmp_path, "-q", "-o", str(tmp_path / "b"))
    assert quiet.stderr == "" and "(reused from an earlier demo)" in quiet.stdout
