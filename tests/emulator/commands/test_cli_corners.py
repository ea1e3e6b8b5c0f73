"""Small corners of the command line on real layouts: the IMU warning of ``run``, ``run`` on a
dataset root, ``info``'s response and calibration, the ``new-method`` hint."""

from __future__ import annotations

import json
import sys
import warnings

import pytest

from emulator.commands.cli import main
from emulator.io.imu import ImuMissingWarning
from tests.emulator.playback.test_playback import write_static_sequence


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("corners") / "seq", n_cycles=2, shape=(32, 48))
    return root


def _run_warnings(args, capsys) -> tuple[int, list[str], str]:
    """(exit code, IMU warning lines on stderr, stderr) of ``exposim ARGS``."""
    import emulator.io.imu as imu

    imu._warned.clear()  # the warning is given once per recording and process
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("default", ImuMissingWarning)
        rc = main(args)
    err = capsys.readouterr().err
    return rc, [ln for ln in err.splitlines() if "no imu/imu.csv" in ln], err


def test_run_without_blur_does_not_warn_about_the_imu(seq, tmp_path, capsys):
    rc, imu_warnings, err = _run_warnings(["run", str(seq), "--methods", "classical-50", "-o", str(tmp_path / "r"),
                                           "--no-progress"], capsys)
    assert rc == 0 and imu_warnings == [] and "imu" not in err


def test_run_with_blur_says_the_imu_is_missing(seq, tmp_path, capsys):
    rc, imu_warnings, err = _run_warnings(["run", str(seq), "--methods", "classical-50", "-o", str(tmp_path / "r"),
                                           "--blur", "consistent", "--no-progress"], capsys)
    assert rc == 1 and "--blur consistent needs the recording's gyro (imu/imu.csv)" in err
    assert len(imu_warnings) == 1 and "no imu/imu.csv" in imu_warnings[0]


def test_dataset_run_without_blur_does_not_warn_about_the_imu(seq, tmp_path, capsys):
    import shutil

    root = tmp_path / "root"
    shutil.copytree(seq, root / "a")
    rc, imu_warnings, _ = _run_warnings(["run", str(root), "--sequences", "all", "--scheduler", "serial",
                                         "--methods", "classical-50", "-o", str(tmp_path / "d"), "--no-progress"],
                                        capsys)
    assert rc == 0 and imu_warnings == []


def test_run_on_a_dataset_root_names_sequences(seq, tmp_path, capsys):
    import shutil

    root = tmp_path / "root"
    for name in ("walk_a", "walk_b"):
        shutil.copytree(seq, root / name)
    (root / "calibration").mkdir()  # not a recording: not counted
    assert main(["run", str(root), "--methods", "classical-50", "-o", str(tmp_path / "r"), "--no-progress"]) == 1
    err = capsys.readouterr().err.strip()
    assert err == (f"exposim run: error: {root}: a folder of 2 recording(s) (walk_a, walk_b), not one recording; "
                   "pass --sequences all (or --sequences NAME,...) to run them, or give the recording's own folder")
    assert not (tmp_path / "r").exists()
    # a folder that is neither keeps the recording's own error
    assert main(["run", str(root / "calibration"), "-o", str(tmp_path / "r"), "--no-progress"]) == 1
    assert "no camera_left/ or camera_right/ folder" in capsys.readouterr().err


def test_new_method_hint_says_how_to_get_pytest(tmp_path, capsys, monkeypatch):
    """The hint runs pytest, which the 'test' extra installs and 'all' does not: without pytest it says so."""
    assert main(["new-method", "my-ae", "--class-name", "MyAE", "-o", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert "pip install" not in out and f"try it:  cd {tmp_path / 'a'} && python -m pytest -q test_my_ae.py" in out
    monkeypatch.setitem(sys.modules, "pytest", None)  # as when pytest is not installed (find_spec gives None)
    try:
        rc = main(["new-method", "my-ae", "--class-name", "MyAE", "-o", str(tmp_path / "b")])
    finally:
        monkeypatch.undo()
    out = capsys.readouterr().out.splitlines()
    assert rc == 0
    assert out[-2] == "pytest is not installed (the 'all' extra does not bring it): pip install 'exposim[test]'"
    assert out[-1].startswith(f"try it:  cd {tmp_path / 'b'} && python -m pytest -q test_my_ae.py")


def test_the_test_extra_brings_pytest_and_all_does_not():
    import tomllib
    from pathlib import Path

    optional = tomllib.loads((Path(__file__).resolve().parents[3] / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]
    assert any(d.startswith("pytest") for d in optional["test"])
    assert not any("test" in d or "pytest" in d for d in optional["all"])


def test_info_names_the_response_and_the_calibration(sample_seq, capsys):
    calib = sample_seq.parent / "calibration"
    assert main(["info", str(sample_seq)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert f"response   {(calib / 'pcalib_inside1.txt').resolve()}" in lines
    assert (f"calibration {(calib / 'september_2023').resolve()} (named for the recording's month "
            f"(name {sample_seq.name}))") in lines
    assert main(["info", str(sample_seq), "--json", "--calibration", str(calib / "april_2023")]) == 0
    desc = json.loads(capsys.readouterr().out)
    assert desc["response"] == str((calib / "pcalib_inside1.txt").resolve())
    assert desc["calibration"] == {"folder": str((calib / "april_2023").resolve()), "reason": "given (--calibration)"}


def test_info_says_when_nothing_is_found(seq, tmp_path, capsys):
    import shutil

    bare = tmp_path / "bare"
    shutil.copytree(seq, bare)
    shutil.rmtree(bare / "calibration")
    assert main(["info", str(bare), "--json"]) == 0
    desc = json.loads(capsys.readouterr().out)
    assert desc["response"] is None and desc["calibration"]["folder"] is None
    assert "no stereo calibration" in desc["calibration"]["reason"]
    assert main(["info", str(bare)]) == 0
    out = capsys.readouterr().out
    assert "response   none found (exposim run needs --response FILE)" in out and "calibration none: " in out
