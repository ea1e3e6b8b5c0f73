"""exposim info / emulate / run with the recording's gyro: blur table, --from-ms, --blur consistent."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from emulator.commands.cli import main
from emulator.io.blurtable import read_blur_table

SAMPLE_CYCLES = 4


def test_info_json_has_imu_and_blur_per_frame(sample_seq, capsys):
    assert main(["info", str(sample_seq), "--json"]) == 0
    desc = json.loads(capsys.readouterr().out)
    assert desc["imu"]["n_samples"] == 19988
    blur = desc["blur"]
    assert blur["stamp"] == "end" and blur["camera"] == "left"
    assert blur["focal_px"] == 1180.80514  # calibration/september_2023, the recording's month (april: 1168.15)
    n_left = sum(len(c["left"]) for c in desc["cycles"])
    assert len(blur["frames"]) == n_left == 18
    by_exp = {}
    for r in blur["frames"]:
        by_exp.setdefault(r["exposure_ms"], []).append(r["max_px"])
    # at rest (about 1 deg/s): blur grows with exposure, about 1 px at 32 ms
    assert max(by_exp[1.0]) < 0.1 and 0.3 < np.median(by_exp[32.0]) < 1.5
    assert np.median(by_exp[32.0]) > np.median(by_exp[8.0]) > np.median(by_exp[2.0])


def test_info_text_shows_blur_table(sample_seq, capsys):
    assert main(["info", str(sample_seq)]) == 0
    out = capsys.readouterr().out
    assert "imu        19988 samples" in out and "32 ms" in out and "stamp at exposure end" in out


def test_emulate_from_ms_forces_the_bracket(sample_seq, tmp_path, capsys):
    assert main(["emulate", str(sample_seq), "--exposure-ms", "24", "--cycle", "1", "--from-ms", "4",
                 "-o", str(tmp_path), "--json", "--blur", "consistent"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["bracket_ms"] == 4.0 and info["ratio"] == 6.0 and info["blur"] == "consistent"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["left_cycle0001_24ms.png", "right_cycle0001_24ms.png"]
    for cam in ("left", "right"):
        c = info["cameras"][cam]
        assert "/4.0/" in c["source"] and c["blur_mismatch_px"] == 0.0
        assert c["target_blur_px"] > c["source_blur_px"] > 0
    # a bracket the cycle lacks is refused by its flag, before anything is written
    out2 = tmp_path / "x"
    assert main(["emulate", str(sample_seq), "--exposure-ms", "24", "--cycle", "0", "--from-ms", "1",
                 "-o", str(out2)]) == 1
    assert "--from-ms 1" in capsys.readouterr().err and not out2.exists()


def test_emulate_plain_records_the_mismatch(sample_seq, tmp_path, capsys):
    assert main(["emulate", str(sample_seq), "--exposure-ms", "4", "--cycle", "1", "--from-ms", "32",
                 "-o", str(tmp_path), "--json", "--camera", "left"]) == 0
    c = json.loads(capsys.readouterr().out)["cameras"]["left"]
    assert c["blur_mismatch_px"] == pytest.approx(c["source_blur_px"] - c["target_blur_px"])
    assert c["blur_mismatch_px"] > 0  # 32 ms emulated down to 4 ms keeps the 32 ms blur


def test_run_blur_consistent_records_and_resumes(sample_seq, tmp_path, capsys):
    plain, blurred = tmp_path / "plain", tmp_path / "blur"
    base = ["run", str(sample_seq), "--methods", "classical-50,fixed", "--no-progress"]
    assert main(base + ["-o", str(plain)]) == 0
    assert main(base + ["-o", str(blurred), "--blur", "consistent"]) == 0
    rj = json.loads((blurred / "run.json").read_text())
    assert rj["blur"]["mode"] == "consistent" and rj["blur"]["stamp"] == "end"
    assert rj["blur"]["placement"] == "tiled"
    assert json.loads((plain / "run.json").read_text())["blur"] == {"mode": "none"}
    assert not (plain / "blur.csv").exists()
    rows = read_blur_table(blurred)
    assert {r["cycle"] for r in rows} == set(range(SAMPLE_CYCLES))
    for r in rows:
        if r["added"]:
            assert r["target_ms"] > r["bracket_ms"] and r["excess_blur_px"] == 0.0
        else:
            assert r["excess_blur_px"] == pytest.approx(max(0.0, r["source_blur_px"] - r["target_blur_px"]))
    # every method row joins a blur row on (cycle, bracket_ms, target_ms)
    keys = {(r["cycle"], r["bracket_ms"], r["target_ms"]) for r in rows if r["camera"] == "left"}
    with open(blurred / "fixed" / "exposures.csv", newline="") as fh:
        for row in csv.DictReader(fh):
            if float(row["ratio"]) != 1.0:
                assert (int(row["cycle"]), float(row["bracket_ms"]), float(row["target_ms"])) in keys
    # a resume must repeat the choice
    assert main(base + ["-o", str(blurred), "--resume", "--blur", "none"]) == 1
    assert "blur" in capsys.readouterr().err
    assert main(base + ["-o", str(blurred), "--resume", "--blur", "consistent"]) == 0
    capsys.readouterr()
    # a folder written before tiled copies (no "placement": uniform sub-instants) is not resumed by this code
    rj["blur"].pop("placement")
    (blurred / "run.json").write_text(json.dumps(rj))
    assert main(base + ["-o", str(blurred), "--resume", "--blur", "consistent"]) == 1
    assert "blur" in capsys.readouterr().err


def test_info_without_imu_says_so_and_nothing_else_changes(tmp_path, capsys):
    try:
        from tests.emulator.playback.test_playback import write_static_sequence
    except ImportError:
        from tests.test_playback import write_static_sequence
    seq, _ = write_static_sequence(tmp_path / "seq", n_cycles=2, shape=(8, 8))
    assert main(["info", str(seq), "--json"]) == 0
    desc = json.loads(capsys.readouterr().out)
    assert desc["imu"] is None and desc["blur"] is None and desc["n_cycles"] == 2
    assert main(["info", str(seq)]) == 0
    assert "imu        none (no imu/imu.csv)" in capsys.readouterr().out
    assert main(["run", str(seq), "--methods", "fixed", "-o", str(tmp_path / "r"), "--blur", "consistent",
                 "--no-progress"]) == 1
    assert "needs the recording's gyro" in capsys.readouterr().err and not (tmp_path / "r").exists()


def test_emulate_blur_aware_selector(sample_seq, tmp_path, capsys):
    args = ["emulate", str(sample_seq), "--exposure-ms", "12", "--cycle", "1", "--camera", "left", "--json"]
    assert main(args + ["-o", str(tmp_path / "a"), "--blur-aware"]) == 0
    info = json.loads(capsys.readouterr().out)
    # at rest the 16 ms bracket's excess blur (< 0.1 px) costs less than the 8 ms bracket's noise (0.22)
    assert info["selector"] == "blur-aware" and info["bracket_ms"] == 16.0
    assert 0 < info["cameras"]["left"]["blur_mismatch_px"] < 0.2
    assert main(args + ["-o", str(tmp_path / "b"), "--blur-aware", "--selector", "closest"]) == 1
    assert "--blur-aware applies to --selector higher-no-sat" in capsys.readouterr().err


def test_run_blur_aware_selection(sample_seq, tmp_path, capsys):
    base = ["run", str(sample_seq), "--methods", "classical-50,fixed", "--no-progress"]
    out = tmp_path / "aware"
    assert main(base + ["-o", str(out), "--blur", "consistent", "--blur-aware"]) == 0
    rj = json.loads((out / "run.json").read_text())
    assert rj["blur"]["blur_aware"] is True and "--blur-aware" in rj["command"]
    # at rest no bracket's excess blur outweighs the noise: the choices are HigherNoSat's
    plain = tmp_path / "plain"
    assert main(base + ["-o", str(plain), "--blur", "consistent"]) == 0
    for m in ("classical-50", "fixed"):
        a = (out / m / "exposures.csv").read_text()
        assert a == (plain / m / "exposures.csv").read_text()
    # a resume without the flag takes it from run.json; refusals name what is wrong, before any folder
    assert main(base + ["-o", str(out), "--resume"]) == 0
    assert main(base + ["-o", str(tmp_path / "x"), "--blur-aware"]) == 1
    assert "needs blur 'consistent'" in capsys.readouterr().err and not (tmp_path / "x").exists()
    assert main(base + ["-o", str(tmp_path / "y"), "--blur", "consistent", "--blur-aware", "--selector", "closest"]) == 1
    assert "refines selector higher-no-sat" in capsys.readouterr().err and not (tmp_path / "y").exists()
