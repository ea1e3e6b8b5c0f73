"""Whole-dataset runs: discovery (folders and zips), units, the summary, resume, failed units, throughput."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from emulator.commands.cli import main
from emulator.orchestration.datasetrun import (BOREALHDR_FULL, DatasetRunError, discover_sequences, plan_groups, plan_units,
                                 project_throughput, throughput)

try:
    from tests.emulator.playback.test_playback import write_static_sequence
    from tests.emulator.io.test_zip import zip_folder
except ImportError:  # tests collected as a package
    from tests.test_playback import write_static_sequence
    from tests.test_zip import zip_folder

METHODS = "classical-50,zhang,fixed"


def make_dataset(root: Path) -> Path:
    """seqA (a folder, 4 cycles) and seqB (a zip with a folder prefix and lidar data, 3 cycles) under
    ``root``, the calibration beside them (BorealHDR layout), and an unrelated file."""
    write_static_sequence(root / "seqA", n_cycles=4, shape=(32, 48))
    b, _ = write_static_sequence(root.parent / f"{root.name}-b", n_cycles=3, shape=(32, 48), k=150.0)
    zip_folder(b, root / "seqB.zip", "x/seqB", extra={"x/seqB/lidar/0.bin": b"\0" * 8, "x/imu.csv": b"0\n"})
    shutil.copytree(b / "calibration", root / "calibration")
    (root / "notes.txt").write_text("not a sequence\n")
    return root


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp("ds") / "root")


@pytest.fixture(scope="module")
def serial_run(dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("serial") / "out"
    assert main(["run", str(dataset), "--sequences", "all", "--methods", METHODS, "-o", str(out),
                 "--scheduler", "serial", "--group-size", "1", "--no-progress"]) == 0
    return out


def csv_bytes(out: Path) -> dict[str, bytes]:
    """``sequence/method`` -> exposures.csv bytes, whatever the grouping."""
    return {f"{p.parts[-4]}/{p.parts[-2]}": p.read_bytes() for p in sorted(out.glob("*/*/*/exposures.csv"))}


def test_discover_folders_and_zips(dataset, tmp_path):
    found = discover_sequences(dataset)
    assert found == {"seqA": dataset / "seqA", "seqB": dataset / "seqB.zip"}
    assert list(discover_sequences(dataset, "seqB, seqA")) == ["seqB", "seqA"]
    assert discover_sequences(dataset / "seqA") == {"seqA": dataset / "seqA"}  # one recording is its own dataset
    with pytest.raises(DatasetRunError, match="no sequence named nope; found: seqA, seqB"):
        discover_sequences(dataset, "seqA,nope")
    shutil.copytree(dataset / "seqA", tmp_path / "seqA")
    (tmp_path / "seqA.zip").write_bytes(b"")
    with pytest.raises(DatasetRunError, match="'seqA' is there twice"):
        discover_sequences(tmp_path)
    with pytest.raises(DatasetRunError, match="no sequence"):
        discover_sequences(dataset / "calibration")


def test_plan_units():
    assert plan_groups(["a", "b", "c"], 2) == [("a", "b"), ("c",)]
    units = plan_units({"s1": Path("/d/s1"), "s2": Path("/d/s2.zip")}, ["a", "b", "c"], 2)
    assert [u.key for u in units] == ["s1/a+b", "s1/c", "s2/a+b", "s2/c"]
    with pytest.raises(DatasetRunError, match="group size"):
        plan_groups(["a"], 0)


def test_serial_run_layout_and_summary(serial_run, dataset, tmp_path):
    cfg = json.loads((serial_run / "dataset.json").read_text())
    assert cfg["sequences"] == {"seqA": str(dataset / "seqA"), "seqB": str(dataset / "seqB.zip")}
    res = json.loads((serial_run / "results.json").read_text())
    assert [u["sequence"] + "/" + u["group"] for u in res["units"]] == [
        f"{s}/{m}" for s in ("seqA", "seqB") for m in METHODS.split(",")]
    assert res["errors"] == [] and (serial_run / "methods.png").stat().st_size > 1000
    # every unit folder is the run folder `exposim run SEQ --methods M` writes: same CSV bytes
    assert main(["run", str(dataset / "seqB.zip"), "--methods", METHODS, "-o", str(tmp_path / "single"),
                 "--no-progress"]) == 0
    for m in METHODS.split(","):
        assert (serial_run / "seqB" / m / m / "exposures.csv").read_bytes() == \
            (tmp_path / "single" / m / "exposures.csv").read_bytes()
    single = json.loads((tmp_path / "single" / "results.json").read_text())["methods"]
    for m in METHODS.split(","):
        assert res["per_sequence"]["seqB"][m]["mean_exposure_ms"] == single[m]["mean_exposure_ms"]
    # per-method table: cycle-weighted mean over the two sequences (4 and 3 cycles)
    a, b = res["per_sequence"]["seqA"]["zhang"], res["per_sequence"]["seqB"]["zhang"]
    assert res["per_method"]["zhang"]["cycles"] == 7
    assert res["per_method"]["zhang"]["mean_exposure_ms"] == pytest.approx(
        (4 * a["mean_exposure_ms"] + 3 * b["mean_exposure_ms"]) / 7, rel=1e-12)
    t = res["throughput"]
    assert t["cycles"] == 7 and t["images"] == 42  # 6 shots per cycle, a stereo pair counted once
    assert t["images_per_s_one_worker"] == pytest.approx(6 * t["cycles_per_s_one_worker"])
    assert [p["n_workers"] for p in t["projection"]] == [1, 2, 8, 16, 55]
    assert "Projection to the full BorealHDR dataset" in (serial_run / "report.md").read_text()


def test_grouping_does_not_change_the_csvs(serial_run, dataset, tmp_path):
    out = tmp_path / "grouped"
    assert main(["run", str(dataset), "--sequences", "all", "--methods", METHODS, "-o", str(out),
                 "--scheduler", "serial", "--group-size", "2", "--no-progress"]) == 0
    assert sorted(p.name for p in (out / "seqA").iterdir()) == ["classical-50+zhang", "fixed"]
    assert csv_bytes(out) == csv_bytes(serial_run) and len(csv_bytes(out)) == 6
    whole = tmp_path / "whole"  # default: one unit per sequence
    assert main(["run", str(dataset), "--sequences", "seqB", "--methods", METHODS, "-o", str(whole),
                 "--scheduler", "serial", "--no-progress"]) == 0
    assert [p.name for p in (whole / "seqB").iterdir()] == ["classical-50+zhang+fixed"]
    assert csv_bytes(whole) == {k: v for k, v in csv_bytes(serial_run).items() if k.startswith("seqB/")}


def test_resume_keeps_finished_units(serial_run, tmp_path, capsys):
    out = tmp_path / "out"
    shutil.copytree(serial_run, out)
    kept = {p: p.read_bytes() for p in out.glob("*/*/run.json")}
    shutil.rmtree(out / "seqA" / "zhang")
    (out / "seqA" / ".zhang.staging-0123456789ab" / "zhang").mkdir(parents=True)  # left by a killed unit
    del kept[out / "seqA" / "zhang" / "run.json"]
    (out / "seqB" / "fixed" / "results.json").unlink()  # killed between its rename and its report
    root = json.loads((out / "dataset.json").read_text())["root"]
    assert main(["run", root, "--sequences", "all", "-o", str(out), "--no-progress"]) == 1
    assert "holds a dataset run; use --resume" in capsys.readouterr().err
    # methods and options come from dataset.json
    assert main(["run", root, "-o", str(out), "--sequences", "all", "--resume", "--scheduler", "serial",
                 "--no-progress"]) == 0
    assert {p: p.read_bytes() for p in kept} == kept  # not recomputed: run.json (timing, creation time) as it was
    assert json.loads((out / "seqB" / "fixed" / "results.json").read_text())["methods"]["fixed"]["cycles"] == 3
    assert csv_bytes(out) == csv_bytes(serial_run)
    assert not list(out.glob("*/.*staging*"))
    res = json.loads((out / "results.json").read_text())
    assert [u["sequence"] + "/" + u["group"] for u in res["units"] if not u["reused"]] == ["seqA/zhang"]
    assert main(["run", root, "--sequences", "all", "--methods", "fixed", "-o", str(out), "--resume",
                 "--scheduler", "serial", "--no-progress"]) == 1
    assert "different configuration (methods)" in capsys.readouterr().err


def test_a_bad_sequence_fails_alone(dataset, tmp_path, capsys):
    root = tmp_path / "root"
    shutil.copytree(dataset, root)
    (root / "broken.zip").write_bytes(b"PK\x03\x04 truncated")
    out = tmp_path / "out"
    assert main(["run", str(root), "--sequences", "all", "--methods", "fixed", "-o", str(out),
                 "--scheduler", "serial", "--no-progress"]) == 1
    err = capsys.readouterr().err.strip()
    assert "1 unit(s) failed" in err and "broken/fixed" in err and "not a readable zip archive" in err
    res = json.loads((out / "results.json").read_text())
    assert [e["unit"] for e in res["errors"]] == ["broken/fixed"]
    assert [u["sequence"] for u in res["units"]] == ["seqA", "seqB"]  # the others are kept
    assert main(["run", str(root), "--scheduler", "local", "-o", str(tmp_path / "x")]) == 1
    assert "a single sequence runs serially" in capsys.readouterr().err


def test_projection_arithmetic():
    p = project_throughput(0.5, 6.0, 8)
    cycles = 393_238 / 6
    assert p["dataset_cycles"] == pytest.approx(cycles, rel=1e-15)
    assert p["wall_hours"] == pytest.approx(cycles * 0.5 / 8 / 3600, rel=1e-15)
    assert p["worker_hours"] == pytest.approx(cycles * 0.5 / 3600, rel=1e-15)
    assert p["cycles_per_s"] == pytest.approx(16.0, rel=1e-15)  # 8 workers / 0.5 s per cycle
    assert p["images_per_s"] == pytest.approx(96.0, rel=1e-15)
    assert p["real_time_factor"] == pytest.approx(18000 / (cycles * 0.5 / 8), rel=1e-15)
    # no more busy workers than units: 55 trajectories x 2 groups
    big = project_throughput(0.5, 6.0, 1000, n_units_per_trajectory=2)
    assert big["busy_workers"] == 110 and big["cycles_per_s"] == pytest.approx(220.0, rel=1e-15)
    assert BOREALHDR_FULL == {"trajectories": 55, "images": 393_238, "duration_s": 18000.0}
    with pytest.raises(ValueError):
        project_throughput(0.0, 6.0, 1)


def test_throughput_from_unit_records():
    recs = [
        {"sequence": "a", "n_cycles": 10, "n_images": 60, "loop_s": 2.0, "reused": False, "n_brackets": 6},
        {"sequence": "a", "n_cycles": 10, "n_images": 60, "loop_s": 3.0, "reused": True, "n_brackets": 6},
        {"sequence": "b", "n_cycles": 5, "n_images": 30, "loop_s": 1.0, "reused": False, "n_brackets": 6},
        {"sequence": "b", "n_cycles": 5, "n_images": 30, "loop_s": 1.5, "reused": False, "n_brackets": 6},
    ]
    t = throughput(recs, wall_s=2.0, n_groups=2, workers=[4])
    assert (t["cycles"], t["images"], t["worker_s"]) == (15, 90, 7.5)
    assert t["seconds_per_cycle"] == 0.5 and t["cycles_per_s_one_worker"] == 2.0 and t["images_per_s_one_worker"] == 12.0
    assert t["per_sequence"]["a"]["cycles_per_s"] == 2.0 and t["per_sequence"]["b"]["images_per_s"] == 12.0
    # computed now: 3 units = 1.5 sequence-sweeps of (10 + 5 + 5) / 2 = 10 cycles in 2 s
    assert t["cycles_per_s_wall"] == 5.0 and t["units_computed"] == 3
    assert t["images_per_cycle"] == 6
    assert t["projection"][0]["wall_hours"] == pytest.approx(393_238 / 6 * 0.5 / 4 / 3600, rel=1e-15)
    # without the bracket count: the measured images per cycle (here 6 as well)
    t2 = throughput([{k: v for k, v in r.items() if k != "n_brackets"} for r in recs], wall_s=2.0, n_groups=2,
                    workers=[4])
    assert t2["images_per_cycle"] == 6.0 and t2["projection"] == t["projection"]


def test_method_intervals_over_sequences():
    from emulator.report.dataset import method_intervals

    per_seq = {f"s{k}": {"a": {"mean_exposure_ms": 4.0 + k, "mean_saturated_fraction": 0.10 + 0.01 * k},
                         "b": {"mean_exposure_ms": 8.0 + k, "mean_saturated_fraction": 0.02 + 0.01 * k}}
               for k in range(6)}
    iv = method_intervals(per_seq, ["a", "b"])
    sat = iv["mean_saturated_fraction"]
    assert sat["best"] == "b"
    d = sat["methods"]["a"]["difference_to_best"]
    # paired by sequence: the difference is 0.08 on every sequence, so its interval is exactly [0.08, 0.08]
    assert d["estimate"] == pytest.approx(0.08) and d["ci95"] == pytest.approx([0.08, 0.08]) and d["excludes_zero"]
    assert iv["mean_exposure_ms"]["methods"]["a"]["estimate"] == pytest.approx(6.5)
