"""``exposim run``: run folder layout, refusal to overwrite, --resume after an interruption."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from emulator.cli import main
from emulator.playback import CSV_COLUMNS, PlaybackError, run_to_folder
from test_playback import write_static_sequence

METHODS = "classical-50,kim,zhang,fixed"


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("cli") / "seq", n_cycles=6, shape=(32, 48))
    return root


def _files(run_dir):
    return {p.relative_to(run_dir).as_posix(): p.read_bytes() for p in sorted(run_dir.rglob("*"))
            if p.is_file() and p.suffix in (".csv", ".png", ".txt") and p.name != "exposure.png"}


@pytest.fixture(scope="module")
def clean_run(seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("clean") / "run"
    assert main(["run", str(seq), "--methods", METHODS, "-o", str(out), "--save", "png16", "--no-progress"]) == 0
    return out


def test_layout_and_contract(clean_run, seq):
    info = json.loads((clean_run / "run.json").read_text())
    assert info["methods"] == METHODS.split(",") and info["save"] == "png16" and info["status"] == "complete"
    assert info["sequence"] == str(seq.resolve()) and info["white_level"] == 4095
    assert info["command"].startswith("exposim run ") and "--save png16" in info["command"]
    assert info["method_options"]["kim"]["seed"] == 0 and info["method_options"]["zhang"]["mode"] == "paper"
    results = json.loads((clean_run / "results.json").read_text())
    for name in METHODS.split(","):
        header = (clean_run / name / "exposures.csv").read_text().splitlines()[0].split(",")
        assert tuple(header[: len(CSV_COLUMNS)]) == CSV_COLUMNS
        lefts = sorted((clean_run / name / "images" / "left").iterdir())
        rights = sorted((clean_run / name / "images" / "right").iterdir())
        assert [p.name for p in lefts] == [p.name for p in rights] and len(lefts) == 6
        assert cv2.imread(str(lefts[0]), cv2.IMREAD_UNCHANGED).dtype == np.uint16
        times = (clean_run / name / "images" / "times.txt").read_text().splitlines()
        assert [f"{line.split()[0]}.png" for line in times] == [p.name for p in lefts]
        assert results["methods"][name]["cycles"] == 6
    for f in ("exposure.png", "report.md", "results.json"):
        assert (clean_run / f).is_file()


def test_png8_is_rounded_gray(seq, tmp_path):
    out = tmp_path / "run8"
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(out), "--save", "png8", "--no-progress"]) == 0
    p16 = tmp_path / "run16"
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(p16), "--save", "png16", "--no-progress"]) == 0
    name = sorted((out / "classical-50" / "images" / "left").iterdir())[2].name
    g8 = cv2.imread(str(out / "classical-50" / "images" / "left" / name), cv2.IMREAD_UNCHANGED)
    raw = cv2.imread(str(p16 / "classical-50" / "images" / "left" / name), cv2.IMREAD_UNCHANGED)
    gray = cv2.cvtColor(raw, cv2.COLOR_BayerRG2GRAY)
    assert g8.dtype == np.uint8 and np.array_equal(g8, np.rint(gray.astype(np.float64) * 255 / 4095).astype(np.uint8))


def test_refuses_to_overwrite(clean_run, seq, capsys):
    assert main(["run", str(seq), "--methods", "fixed", "-o", str(clean_run), "--no-progress"]) == 1
    assert "refusing to overwrite" in capsys.readouterr().err


def test_unknown_method_is_one_line_error(seq, tmp_path, capsys):
    assert main(["run", str(seq), "--methods", "fixed,bogus", "-o", str(tmp_path / "x"), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "unknown AE method" in err and "bogus" in err and len(err.strip().splitlines()) == 1


def _interrupted_run(seq, out, after):
    def stop(done, total):
        if done == after:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_to_folder(seq, METHODS.split(","), out, save="png16", progress=stop,
                      command="exposim run (interrupted in a test)")
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "interrupted" and info["cycles_done"] == after


def test_resume_continues_to_the_same_result(clean_run, seq, tmp_path):
    out = tmp_path / "run"
    _interrupted_run(seq, out, after=3)
    # a torn last line, as if killed while writing a row
    with open(out / "kim" / "exposures.csv", "a") as fh:
        fh.write("3,17000000001363636")
    assert main(["run", str(seq), "-o", str(out), "--resume", "--no-progress"]) == 0
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "complete" and info["cycles_done"] == 6 and info["resumed"] == 1
    assert _files(out) == _files(clean_run)


def test_resume_detects_a_different_replay(seq, tmp_path, capsys):
    out = tmp_path / "run"
    _interrupted_run(seq, out, after=2)
    path = out / "classical-50" / "exposures.csv"
    lines = path.read_text().splitlines()
    fields = lines[2].split(",")
    fields[2] = "4.5"  # a recorded target that the replay will not produce
    lines[2] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(PlaybackError, match="differs from the recorded row"):
        run_to_folder(seq, METHODS.split(","), out, save="png16", resume=True)
    assert main(["run", str(seq), "-o", str(out), "--resume", "--mode", "borealhdr", "--no-progress"]) == 1
    assert "different configuration (mode)" in capsys.readouterr().err


def test_resume_without_a_run_folder(seq, tmp_path, capsys):
    assert main(["run", str(seq), "-o", str(tmp_path / "none"), "--resume", "--no-progress"]) == 1
    assert "no run to resume" in capsys.readouterr().err


def test_options_and_jobs(seq, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    common = ["--methods", "kim,shim", "--option", "kim.window=3", "--seed", "2", "--mode", "borealhdr",
              "--initial-ms", "2.5", "--range-ms", "0.1", "30", "--no-progress"]
    assert main(["run", str(seq), "-o", str(a), *common]) == 0
    assert main(["run", str(seq), "-o", str(b), "--jobs", "2", *common]) == 0
    info = json.loads((a / "run.json").read_text())
    assert info["method_options"]["kim"]["window"] == 3 and info["method_options"]["kim"]["seed"] == 2
    assert info["range_ms"] == [0.1, 30.0] and info["initial_ms"] == 2.5
    for name in ("kim", "shim"):
        assert (a / name / "exposures.csv").read_bytes() == (b / name / "exposures.csv").read_bytes()
