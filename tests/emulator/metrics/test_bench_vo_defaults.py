"""``bench vo`` with no extra flags: calibration from the layout, extrinsics refined where the
data need it (measured), what cannot be computed said in words, evo-named outputs."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from emulator.commands.cli import main
from emulator.metrics.bench import no_reference_note, REFINE_THRESHOLD_FRACTION, bench_vo, evo_result_path
from emulator.metrics.vo import VOParameters

from tests.conftest import SAMPLE_SEQ, missing_shared

try:
    from tests.emulator.metrics.test_metrics_vo import make_synthetic_run
except ImportError:  # tests collected as a package
    from tests.test_metrics_vo import make_synthetic_run

THRESHOLD_PX = REFINE_THRESHOLD_FRACTION * VOParameters().max_row_diff_px


@pytest.fixture(scope="module")
def pitched(tmp_path_factory):
    """The BorealHDR September 2023 situation: the files claim a parallel rig, the right
    camera is pitched by 0.8 deg (about 2.7 px at this focal length)."""
    return make_synthetic_run(tmp_path_factory.mktemp("pitched"), n_frames=3, methods=("fixed", "shim"),
                              right_pitch_deg=0.8)


@pytest.fixture(scope="module")
def parallel(tmp_path_factory):
    return make_synthetic_run(tmp_path_factory.mktemp("parallel"), n_frames=3)


def test_auto_refines_a_pitched_rig_and_records_why(pitched, tmp_path):
    results = bench_vo(pitched["run"], tmp_path / "out", deltas_m=[0.17])
    ext = results["calibration"]["extrinsics"]
    assert ext["mode"] == "auto" and ext["refined"] is True
    assert ext["epipolar_residual_px"] > 2.0  # f tan(0.8 deg) = 2.7 px
    assert ext["estimate"]["epipolar_residual_after_px"] < 0.5
    assert ext["threshold_px"] == THRESHOLD_PX
    assert ext["estimate"]["rotation_deg"][0] == pytest.approx(-0.8, abs=0.05)  # the pitch that was put in
    assert ext["estimate"]["rotation_deg"][1] == 0.0  # yaw and baseline direction stay as calibrated
    for m in results["methods"].values():  # depth scale intact: the VO agrees with the ground truth
        assert m["status"] == "success"
        assert m["rpe"]["scale"] == pytest.approx(1.0, abs=0.02)
        assert m["rpe"]["deltas"][0]["trans_pct"]["median"] < 2.0
    assert results["calibration"]["choice"]["reason"] == "the recording's own calibration/ folder"
    # the same data without refinement: stereo depth is lost, and the results say so in words
    plain = bench_vo(pitched["run"], tmp_path / "plain", deltas_m=[0.17], refine_extrinsics=0, methods=["fixed"])
    assert plain["calibration"]["extrinsics"]["refined"] is False
    assert plain["methods"]["fixed"]["failures"][0]["reason"] == "too_few_stereo_points"
    assert any("lost track" in n and "--rpe-on-failure" in n for n in plain["limitations"])


def test_auto_keeps_a_calibration_that_fits(parallel, tmp_path):
    results = bench_vo(parallel["run"], tmp_path / "out", deltas_m=[0.17])
    ext = results["calibration"]["extrinsics"]
    assert ext["refined"] is False and ext["epipolar_residual_px"] < THRESHOLD_PX
    assert results["calibration"]["refined_extrinsics"] is None
    assert results["limitations"] == []


def test_evo_named_trajectories_and_result_files(pitched, tmp_path):
    from evo.tools import file_interface

    out = tmp_path / "vo"
    results = bench_vo(pitched["run"], out, deltas_m=[0.17, 0.35])
    for name in ("fixed", "shim"):
        traj = file_interface.read_tum_trajectory_file(out / f"{name}.txt")  # header comment skipped by evo
        assert traj.num_poses == 3
        assert (out / f"{name}.txt").read_text().startswith(f"# exposim bench vo estimate: method {name}")
        for delta in (0.17, 0.35):
            res = file_interface.load_res_file(evo_result_path(out, "trans", delta, name), load_trajectories=True)
            assert res.info["est_name"] == name
            entry = next(e for e in results["methods"][name]["rpe"]["deltas"] if e["delta_m"] == delta)
            assert res.np_arrays["error_array"].size == entry["n_pairs"]
            assert {"reference", name} <= set(res.trajectories)
    exe = shutil.which("evo_traj")
    if exe:  # evo_traj tum OUT/*.txt names each trajectory by its method
        done = subprocess.run([exe, "tum", *sorted(str(p) for p in out.glob("*.txt")), "--no_warnings"],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        assert "name:\tfixed" in done.stdout and "name:\tshim" in done.stdout
    exe = shutil.which("evo_res")
    if exe:  # evo's own tool reads them and labels each by method
        zips = sorted(str(p) for p in (out / "evo" / "rpe_trans_0.17m").glob("*.zip"))
        done = subprocess.run([exe, *zips, "--no_warnings"], capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        assert "fixed" in done.stdout and "shim" in done.stdout


def test_no_reference_is_said_once_in_words(parallel, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(parallel["run"], run)
    seq = tmp_path / "seq"
    shutil.copytree(parallel["sequence"], seq)
    shutil.rmtree(seq / "ground_truth")
    meta = json.loads((run / "run.json").read_text())
    meta["sequence"] = str(seq)
    (run / "run.json").write_text(json.dumps(meta))
    code = main(["bench", "vo", str(run), "-o", str(tmp_path / "out")])
    _, err = capsys.readouterr()
    assert code == 0, err
    assert err.count("RPE not computed: no reference trajectory") == 1
    assert "lidar" in err and "--reference" in err
    results = json.loads((tmp_path / "out" / "results.json").read_text())
    assert results["limitations"] == [no_reference_note(seq)]
    # the note names the recording actually used, not the shared sample
    assert "The recording seq has none (no ground_truth/poses_left.txt in it" in results["limitations"][0]
    assert "shared BorealHDR sample" not in err and "shared BorealHDR sample" not in results["limitations"][0]
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## What could not be computed, and why" in report and "--reference FILE" in report
    assert not (tmp_path / "out" / "evo").exists()
    # issue 46: without a reference the methods are ranked on the VO table; no empty RPE plot
    assert not (tmp_path / "out" / "fig6_rpe.png").exists() and (tmp_path / "out" / "trajectories.png").is_file()
    assert "fig6_rpe.png" not in report and "fig6_rpe.png" not in err
    assert sorted(results["ranking_without_reference"]) == sorted(results["methods"])
    row = next(line for line in report.splitlines() if line.startswith("| 1 | "))
    first = results["methods"][results["ranking_without_reference"][0]]["summary"]
    assert row.endswith(f"| {first['n_tracked']}/{first['n_frames']} | {first['median_stereo_points']:.0f} | "
                        f"{first['median_inliers']:.0f} | {first['median_row_offset_px']:.2f} | "
                        f"{first['path_length_m']:.3f} |")
    assert first["n_tracked"] == first["n_frames"] == 3 and first["path_length_m"] > 0
    assert "VO by method, without a reference" in (tmp_path / "out" / "report.html").read_text()
    # stderr is not a terminal here: one line as each method starts and ends
    assert "exposim bench vo [" in err and ": VO fixed 0/3" in err and ": VO fixed 3/3" in err


def test_failed_bench_leaves_no_output_folder(parallel, tmp_path, capsys):
    code = main(["bench", "vo", str(parallel["run"]), "--calibration", str(tmp_path / "nope"), "-o",
                 str(tmp_path / "out")])
    _, err = capsys.readouterr()
    assert code == 1 and "nope" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_real_sample_with_no_extra_flags(tmp_path, capsys):
    """`exposim run` on the shared sample, then `bench vo RUN -o OUT` with no calibration flag."""
    if not SAMPLE_SEQ.is_dir():
        missing_shared("shared BorealHDR sample not available")
    run = tmp_path / "run"
    assert main(["run", str(SAMPLE_SEQ), "--methods", "fixed", "--save", "png16", "-o", str(run),
                 "--no-progress"]) == 0
    capsys.readouterr()
    code = main(["bench", "vo", str(run), "-o", str(tmp_path / "vo"), "--max-frames", "3", "--scale", "0.5"])
    _, err = capsys.readouterr()
    assert code == 0, err
    results = json.loads((tmp_path / "vo" / "results.json").read_text())
    assert Path(results["calibration"]["folder"]).name == "september_2023"
    ext = results["calibration"]["extrinsics"]
    assert ext["refined"] and ext["epipolar_residual_px"] > 10  # 16-17 px measured
    assert ext["estimate"]["epipolar_residual_after_px"] < 1.0
    assert results["methods"]["fixed"]["status"] == "success"
    assert "RPE not computed" in err and "september_2023" in err
