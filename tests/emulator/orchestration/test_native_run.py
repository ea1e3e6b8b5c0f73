"""``exposim run --rate native``: one row per recorded frame, resume and --jobs give the same tables, the CLI."""

from __future__ import annotations

import json
import warnings

import pytest


from emulator.commands.cli import main
from emulator.io.runcsv import CSV_COLUMNS, EXTRA_COLUMNS, NATIVE_COLUMNS
from emulator.orchestration.runner import run_to_folder
from tests.conftest import static_chart_recording  # noqa: E402

W, H = 40, 24
METHODS = "classical-50,shim,zhang,fixed"


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A static stereo chart, 3 sweeps started mid-sweep, no IMU."""
    return static_chart_recording(tmp_path_factory.mktemp("nrun") / "static", W, H, dynamic_range_db=50.0,
                                  n_shots=16, noise=True, start_bracket_index=3)


def _run(seq, out, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_to_folder(seq, METHODS, out, rate="native", save="png16", **kw)


def _tables(out):
    return {m: (out / m / "exposures.csv").read_bytes() for m in METHODS.split(",")}


def test_one_row_per_frame_and_the_record(recording, tmp_path):
    summary = _run(recording, tmp_path / "run")
    assert summary["rate"] == "native" and summary["latency_frames"] == 1 and summary["n_frames"] == 16
    run_json = json.loads((tmp_path / "run" / "run.json").read_text())
    assert run_json["rate"] == "native" and run_json["native"]["warp"] == "none"
    first = run_json["native"]["benchmarked_frames"]
    for m in METHODS.split(","):
        lines = (tmp_path / "run" / m / "exposures.csv").read_text().splitlines()
        assert lines[0].split(",") == list(CSV_COLUMNS + EXTRA_COLUMNS + NATIVE_COLUMNS)
        rows = [dict(zip(lines[0].split(","), r.split(","))) for r in lines[1:]]
        assert [int(r["cycle"]) for r in rows] == list(range(16))  # one row per recorded frame
        assert [int(r["benchmarked"]) for r in rows] == [int(k in first) for k in range(16)]
        assert sorted({int(r["recorder_cycle"]) for r in rows}) == [0, 1, 2, 3]
        for r in rows:  # a neighbour without a gyro: no warp angle; its own frame: 0
            assert (r["warp_deg"] == "") == (int(r["source_offset"]) != 0)
        assert sum(summary["methods"][m]["source_offsets"].values()) == 16
        # the images: one per frame, at the frame's own instant
        assert len(list((tmp_path / "run" / m / "images" / "left").glob("*.png"))) == 16
    # benchmarked: the first shot of each sweep (8, 16, 32 | 1 ... 32 | 1 ... 32 | 1 ms), the native live
    # condition's instant
    assert first == [0, 3, 9, 15]


def test_resume_after_an_interrupt_gives_the_same_bytes(recording, tmp_path):
    _run(recording, tmp_path / "whole")

    def stop(done, total):
        if done == 7:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _run(recording, tmp_path / "cut", progress=stop)
    assert json.loads((tmp_path / "cut" / "run.json").read_text())["status"] == "interrupted"
    _run(recording, tmp_path / "cut", resume=True)
    assert _tables(tmp_path / "cut") == _tables(tmp_path / "whole")


def test_two_jobs_give_the_tables_of_one(recording, tmp_path):
    _run(recording, tmp_path / "one")
    _run(recording, tmp_path / "two", jobs=2)
    assert _tables(tmp_path / "two") == _tables(tmp_path / "one")


def test_cli_warns_once_without_an_imu_and_refuses_a_lone_latency(recording, tmp_path, capsys):
    assert main(["run", str(recording), "-o", str(tmp_path / "cli"), "--methods", "classical-50", "--rate", "native",
                 "--latency-frames", "2", "-q"]) == 0
    out, err = capsys.readouterr()
    warned = [line for line in err.splitlines() if "warning" in line]
    assert len(warned) == 1 and "without undoing the camera's rotation" in warned[0], err
    assert "frames      16/16 (native rate)" in out
    assert json.loads((tmp_path / "cli" / "run.json").read_text())["latency_frames"] == 2
    assert main(["run", str(recording), "-o", str(tmp_path / "cli2"), "--latency-frames", "2", "-q"]) == 1
    assert "--latency-frames 2: used only with --rate native" in capsys.readouterr().err
    assert not (tmp_path / "cli2").exists()


def test_benchmarks_read_one_frame_per_recorder_cycle(recording, tmp_path):
    from emulator.io.runfolder import read_run_folder
    from emulator.metrics.bench import bench_features
    from emulator.metrics.bench_common import benchmark_frames

    _run(recording, tmp_path / "run")
    run = read_run_folder(tmp_path / "run")
    picked = benchmark_frames(run)
    first = json.loads((tmp_path / "run" / "run.json").read_text())["native"]["benchmarked_frames"]
    for m, method in picked.methods.items():  # the frames at each sweep's first shot, in time order
        assert [f.timestamp_ns for f in method.frames] == [run.methods[m].frames[k].timestamp_ns for k in first]
    assert benchmark_frames(run, every_frame=True) is run
    res = bench_features(tmp_path / "run", tmp_path / "feat", methods=["classical-50"])
    assert res["methods"]["classical-50"]["n_images"] == 4
    res = bench_features(tmp_path / "run", tmp_path / "feat_all", methods=["classical-50"], every_frame=True)
    assert res["methods"]["classical-50"]["n_images"] == 16 and res["parameters"]["every_frame"] is True


def test_dataset_run_on_threads_with_a_zip_gives_the_single_runs_tables(tmp_path, capsys):
    from tests.emulator.orchestration.test_datasetrun import make_dataset

    root = make_dataset(tmp_path / "root")
    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["run", str(root), "--sequences", "all", "--methods", "classical-50,fixed", "--rate", "native",
                     "-o", str(out), "--scheduler", "threads", "--workers", "2", "--group-size", "1",
                     "--no-progress"]) == 0
        assert main(["run", str(root / "seqB.zip"), "--methods", "classical-50,fixed", "--rate", "native",
                     "-o", str(tmp_path / "single"), "--no-progress"]) == 0
    for m in ("classical-50", "fixed"):
        unit = (out / "seqB" / m / m / "exposures.csv").read_bytes()
        assert unit == (tmp_path / "single" / m / "exposures.csv").read_bytes()
        assert len(unit.decode().splitlines()) == 1 + 18  # 3 sweeps of 6 frames, one row each
        assert len((out / "seqA" / m / m / "exposures.csv").read_text().splitlines()) == 1 + 24
    assert json.loads((out / "dataset.json").read_text())["config"]["rate"] == "native"


def test_the_native_report_says_why_neighbours_went_unwarped():
    """--warp none is said as asked, not as a missing gyro; flow-sharp's on-purpose skips are said under the table."""
    from emulator.report.run import _rate_lines

    summary = {"rate": "native", "latency_frames": 1,
               "methods": {"a": {"source_offsets": {"0": 3, "1": 2}, "unwarped_neighbours": 2}}}
    asked = "\n".join(_rate_lines({"native_warp": "none", "native": {"warp": "none", "window_frames": 12}}, summary))
    assert "not warped (--warp none)" in asked and "no gyro" not in asked
    nogyro = "\n".join(_rate_lines({"native_warp": "rotation", "native": {"warp": "none", "window_frames": 12}}, summary))
    assert "not warped (no gyro)" in nogyro and "on purpose" not in nogyro
    sharp = {"native_warp": "flow-sharp", "native": {"warp": "rotation from the gyro", "warp_mode": "flow-sharp",
                                                     "sharp_motion_px": 1.0, "window_frames": 12}}
    said = "\n".join(_rate_lines(sharp, summary))
    assert "where that moves it 1 px or more" in said and "moved less than 1 px (used as recorded, on purpose)" in said
