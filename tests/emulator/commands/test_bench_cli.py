"""``exposim bench features|vo|rpe``: the command line, its errors, and the evo cross-check."""

from __future__ import annotations

import json
import shutil
import subprocess
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from emulator.commands.cli import main
from emulator.core.gray import bayer_to_gray8
from emulator.io.runfolder import read_run_folder
from emulator.io.tum import read_tum, write_tum

try:
    from tests.emulator.metrics.test_metrics_vo import SHARED, make_synthetic_run
except ImportError:  # tests collected as a package
    from tests.test_metrics_vo import SHARED, make_synthetic_run


def run_cli(capsys, *argv) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


# --------------------------------------------------------------------------- evo cross-check


@pytest.fixture(scope="module")
def trajectory_pair(tmp_path_factory):
    """A smooth 3-D reference and a noisy estimate at 1.1x scale with jittered, partly
    missing timestamps (so the association matters)."""
    root = tmp_path_factory.mktemp("rpe")
    rng = np.random.default_rng(7)
    n = 80
    t = np.linspace(0.0, 8.0, n)
    ref = np.tile(np.eye(4), (n, 1, 1))
    ref[:, :3, :3] = Rotation.from_rotvec(np.c_[0.05 * np.sin(t), 0.3 * t, 0.02 * t]).as_matrix()
    ref[:, :3, 3] = np.c_[np.sin(0.7 * t), 0.1 * np.cos(t), 0.5 * t]
    stamps = (1_695_668_703_000_000_000 + np.rint(t * 1e9)).astype(np.int64)
    est = ref.copy()
    est[:, :3, 3] = 1.1 * ref[:, :3, 3] + rng.normal(0, 0.01, (n, 3))
    est[:, :3, :3] = Rotation.from_rotvec(
        Rotation.from_matrix(ref[:, :3, :3]).as_rotvec() + rng.normal(0, 0.005, (n, 3))
    ).as_matrix()
    keep = np.ones(n, bool)
    keep[[3, 17, 40, 41]] = False
    jitter = rng.integers(-4_000_000, 4_000_000, n)  # +/- 4 ms, below evo's 10 ms
    write_tum(root / "ref.txt", stamps, ref)
    write_tum(root / "est.txt", (stamps + jitter)[keep], est[keep])
    return root / "est.txt", root / "ref.txt"


def evo_rpe_stats(ref: Path, est: Path, out_zip: Path, *args: str) -> dict:
    exe = shutil.which("evo_rpe")
    if exe is None:
        pytest.skip("evo_rpe not on PATH")
    cmd = [exe, "tum", str(ref), str(est), "--pose_relation", "trans_part", *args,
           "--save_results", str(out_zip), "--no_warnings"]
    subprocess.run(cmd, check=True, capture_output=True, timeout=120)
    with zipfile.ZipFile(out_zip) as z:
        return json.loads(z.read("stats.json"))


@pytest.mark.parametrize(
    "ours, theirs",
    [
        ([], []),
        (["--delta", "5", "--align-scale"], ["--delta", "5", "--correct_scale"]),
        (["--delta", "0.5", "--delta-unit", "m"], ["--delta", "0.5", "--delta_unit", "m"]),
        (["--delta", "1", "--delta-unit", "m", "--align-scale"], ["--delta", "1", "--delta_unit", "m", "--correct_scale"]),
    ],
)
def test_bench_rpe_equals_evo_rpe(trajectory_pair, tmp_path, capsys, ours, theirs):
    est, ref = trajectory_pair
    code, out, err = run_cli(capsys, "bench", "rpe", str(ref), str(est), *ours, "--json")  # evo's order
    assert code == 0, err
    assert out.count("\n") == 1  # exactly one JSON object on stdout
    mine = json.loads(out)
    assert set(mine) == {"rmse", "mean", "median"}
    evo = evo_rpe_stats(ref, est, tmp_path / "evo.zip", *theirs)
    for key in ("rmse", "mean", "median"):
        assert mine[key] == pytest.approx(evo[key], abs=1e-9, rel=0)


def test_bench_rpe_errors(trajectory_pair, tmp_path, capsys):
    est, ref = trajectory_pair
    code, out, err = run_cli(capsys, "bench", "rpe", str(tmp_path / "nope.txt"), str(est), "--json")
    assert code == 1 and out == "" and "nope.txt" in err and err.count("\n") == 1
    far = tmp_path / "far.txt"
    write_tum(far, [10**9, 2 * 10**9, 3 * 10**9], np.tile(np.eye(4), (3, 1, 1)))
    code, out, err = run_cli(capsys, "bench", "rpe", str(ref), str(far), "--json")
    assert code == 1 and out == "" and "no timestamps overlap" in err


def test_bench_rpe_takes_evo_order_and_flags_a_swap(trajectory_pair, tmp_path, capsys):
    """REF EST as evo_rpe; evo's own API on the same files gives the same numbers, the swapped
    order different ones, and an estimate given as the reference is flagged."""
    from evo.core import metrics, sync
    from evo.main_rpe import rpe
    from evo.tools import file_interface

    est, ref = trajectory_pair
    code, out, err = run_cli(capsys, "bench", "rpe", str(ref), str(est), "--json")
    assert code == 0, err
    assert f"reference: {ref} (80 poses); estimate: {est} (76 poses) (order REF EST" in err and "warning" not in err
    mine = json.loads(out)
    traj_ref = file_interface.read_tum_trajectory_file(ref)
    traj_est = file_interface.read_tum_trajectory_file(est)
    traj_ref, traj_est = sync.associate_trajectories(traj_ref, traj_est, max_diff=0.01)
    theirs = rpe(traj_ref, traj_est, metrics.PoseRelation.translation_part, delta=1,
                 delta_unit=metrics.Unit.frames).stats
    assert mine["rmse"] == pytest.approx(theirs["rmse"], abs=1e-12, rel=0)
    # 1-frame translation errors are symmetric; with the scale correction (applied to the
    # estimate) the order matters
    _, out_scaled, _ = run_cli(capsys, "bench", "rpe", str(ref), str(est), "--align-scale", "--json")
    _, out_swapped, _ = run_cli(capsys, "bench", "rpe", str(est), str(ref), "--align-scale", "--json")
    assert json.loads(out_swapped)["rmse"] != pytest.approx(json.loads(out_scaled)["rmse"], rel=1e-2)
    # a bench vo estimate (its header) given first: flagged, by name
    vo_est = tmp_path / "fixed.txt"
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[:, 0, 3] = [0.0, 0.1, 0.2]
    stamps = read_tum(ref).timestamps_ns[:3].tolist()
    write_tum(vo_est, stamps, poses, header="exposim bench vo estimate: method fixed")
    code, _, err = run_cli(capsys, "bench", "rpe", str(vo_est), str(ref), "--json")
    assert code == 0
    assert f"warning: the reference {vo_est} looks like an estimate (it was written by exposim bench vo" in err
    assert "earlier" not in err.lower()
    # a reference that starts exactly at the identity (a synthetic one does) against an estimate
    # that does not: no warning, the identity is no evidence of a swap
    plain = tmp_path / "plain.txt"
    write_tum(plain, stamps, poses)
    assert np.array_equal(read_tum(plain).positions[0], [0, 0, 0])
    code, _, err = run_cli(capsys, "bench", "rpe", str(plain), str(ref), "--json")
    assert code == 0 and "warning" not in err
    # both written by bench vo, or neither: nothing tells them apart, no warning
    both = tmp_path / "shim.txt"
    write_tum(both, stamps, poses, header="exposim bench vo estimate: method shim")
    code, _, err = run_cli(capsys, "bench", "rpe", str(vo_est), str(both), "--json")
    assert code == 0 and "warning" not in err
    code, _, err = run_cli(capsys, "bench", "rpe", str(plain), str(vo_est), "--json")
    assert code == 0 and "warning" not in err


def test_bench_rpe_help_speaks_of_the_order_not_its_history(capsys):
    with pytest.raises(SystemExit):
        run_cli(capsys, "bench", "rpe", "--help")
    out = capsys.readouterr().out
    assert "REF then EST" in out or "REF EST" in out
    assert "earlier" not in out.lower() and "EST REF" not in out


# --------------------------------------------------------------------------- features


def write_feature_run(root: Path, methods=("fixed", "dark"), n=3, save="png16") -> Path:
    """A run folder whose methods see a texture moving 6 px per frame; 'dark' at 1/8 of
    the brightness (fewer matches after the fixed 12-to-8-bit scale)."""
    rng = np.random.default_rng(1)
    noise = cv2.GaussianBlur(rng.standard_normal((120, 200)).astype(np.float32), (0, 0), 1.5)
    tex = np.clip(2000 + 600 * noise / noise.std(), 0, 4095)
    root.mkdir(parents=True, exist_ok=True)
    (root / "run.json").write_text(json.dumps({"sequence": None, "methods": list(methods), "save": save}))
    for m, gain in zip(methods, (1.0, 0.125)):
        left = root / m / "images" / "left"
        left.mkdir(parents=True)
        lines = []
        for k in range(n):
            ts = 1_000_000_000 + k * 274_000_000
            img = np.rint(tex[:, 6 * k:6 * k + 160] * gain).astype(np.uint16)
            cv2.imwrite(str(left / f"{ts}.png"), img)
            lines.append(f"{ts} {ts / 1e9:.9f} {4.0 * gain}")
        (root / m / "images" / "times.txt").write_text("\n".join(lines) + "\n")
    return root


@pytest.mark.slow
def test_bench_features_cli(tmp_path, capsys):
    run = write_feature_run(tmp_path / "run")
    out = tmp_path / "out"
    code, stdout, err = run_cli(capsys, "bench", "features", str(run), "-o", str(out), "-q", "--matcher", "bf")
    assert code == 0, err
    results = json.loads((out / "results.json").read_text())
    assert (out / "fig4_features.png").is_file() and (out / "report.md").is_file()
    assert results["command"].startswith("exposim bench features")
    fixed = results["runs"][0]["methods"]["fixed"]
    dark = results["runs"][0]["methods"]["dark"]
    assert len(fixed["uniformity"]) == 3 and len(fixed["matches"]) == 2
    assert min(dark["matches"]) < min(fixed["matches"])
    # one run: the success curve is a step at the run's smallest match count
    taus = np.array(results["success_curve"]["taus"])
    rate = np.array(results["success_curve"]["rate"]["fixed"])
    np.testing.assert_array_equal(rate, (taus <= fixed["min_matches"]).astype(float))
    assert "Fig. 4" in (out / "report.md").read_text()
    # a verdict per result (uniformity, matches, success at tau = 100), in the report and on stderr
    from emulator.report.bench import features_verdicts

    verdicts = features_verdicts(results)
    assert [v.split(" ")[0] for v in verdicts] == ["Median", "Median", "Success"]
    assert all(f"- {v}" in (out / "report.md").read_text() for v in verdicts)
    biggest = max(max(m["matches"]) for m in results["runs"][0]["methods"].values())
    assert (f"at most {biggest})" in verdicts[2]) is (biggest < 100)
    code, _, err = run_cli(capsys, "bench", "features", str(run), "-o", str(tmp_path / "out2"), "--matcher", "bf")
    assert code == 0 and all(f"verdict: {v}" in err for v in verdicts)
    # never overwrite silently
    code, _, err = run_cli(capsys, "bench", "features", str(run), "-o", str(out), "-q")
    assert code == 1 and "results.json: exists; refusing to overwrite" in err and err.count("\n") == 1
    code, _, err = run_cli(capsys, "bench", "features", str(run), "-o", str(out), "-q", "--force",
                           "--methods", "fixed", "--max-frames", "2")
    assert code == 0, err
    assert list(json.loads((out / "results.json").read_text())["methods"]) == ["fixed"]


def test_bench_features_two_runs_and_png8(tmp_path, capsys):
    a = write_feature_run(tmp_path / "a", methods=("fixed",), n=3)
    b = tmp_path / "b"
    write_feature_run(b, methods=("fixed",), n=3)
    levels = read_run_folder(b)
    for p in (b / "fixed" / "images" / "left").glob("*.png"):  # the same run saved as png8
        raw = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(p), bayer_to_gray8(raw, white_level=levels.white_level, black_level=levels.black_level))
    code, _, err = run_cli(capsys, "bench", "features", str(a), str(b), "-o", str(tmp_path / "out"), "-q")
    assert code == 0, err
    results = json.loads((tmp_path / "out" / "results.json").read_text())
    assert results["n_runs"] == 2 and results["methods"]["fixed"]["n_runs"] == 2
    m_a, m_b = (r["methods"]["fixed"] for r in results["runs"])
    assert m_a["n_keypoints"] == m_b["n_keypoints"]  # png8 = png16 after the stated conversion


def test_bench_features_without_images(tmp_path, capsys):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "run.json").write_text(json.dumps({"methods": ["fixed"], "save": "none"}))
    code, out, err = run_cli(capsys, "bench", "features", str(tmp_path / "run"), "-o", str(tmp_path / "out"))
    assert code == 1 and err.count("\n") == 1
    assert "run.json" in err and "saved no images" in err


# --------------------------------------------------------------------------- VO


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    return make_synthetic_run(tmp_path_factory.mktemp("cli_vo"), n_frames=3)


def test_bench_vo_cli(short_run, tmp_path, capsys):
    out = tmp_path / "vo"
    code, _, err = run_cli(capsys, "bench", "vo", str(short_run["run"]), "-o", str(out), "-q", "--deltas", "0.17,0.35")
    assert code == 0, err
    results = json.loads((out / "results.json").read_text())
    m = results["methods"]["fixed"]
    assert m["status"] == "success"
    for entry in m["rpe"]["deltas"]:  # steps of ~0.17 m: one pair per delta length
        assert entry["n_pairs"] >= 1 and entry["trans_pct"]["median"] < 2.0
    assert (out / "fixed.txt").is_file()


def test_bench_vo_bad_reference(short_run, tmp_path, capsys):
    far = tmp_path / "far.txt"
    write_tum(far, [10**9, 2 * 10**9], np.tile(np.eye(4), (2, 1, 1)))
    code, out, err = run_cli(capsys, "bench", "vo", str(short_run["run"]), "--reference", str(far),
                             "-o", str(tmp_path / "out"))
    assert code == 1 and err.count("\n") == 1
    assert "far.txt" in err and "no timestamps overlap" in err
    assert not (tmp_path / "out" / "results.json").exists()


def test_bench_vo_calibration_size_mismatch(short_run, tmp_path, capsys):
    if not SHARED.is_dir():
        from tests.conftest import missing_shared

        missing_shared("shared BorealHDR sample not available")
    code, out, err = run_cli(capsys, "bench", "vo", str(short_run["run"]), "--calibration",
                             str(SHARED / "september_2023"), "-o", str(tmp_path / "out"))
    assert code == 1 and err.count("\n") == 1
    assert "256x192" in err and "1920x1200" in err and "left.yaml" in err


def test_bench_without_subcommand_prints_help(capsys):
    code, out, _ = run_cli(capsys, "bench")
    assert code == 2 and "features" in out and "rpe" in out
