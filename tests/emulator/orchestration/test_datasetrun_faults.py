"""Fault suite, issue 24 (dataset runs): import-path plugins are reported under the name they
ran under, and a plugin that fails in every unit is named in the report with a non-zero exit."""

from __future__ import annotations

import json
import sys

import pytest

from emulator.commands.cli import main
from tests.emulator.playback.test_playback import write_static_sequence

PLUG = '''
class Steady:
    name = "steady"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        return 5.0


class Broken:
    name = "broken"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        raise RuntimeError("always")


class Exits:
    name = "exits"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        import sys

        sys.exit(0)
'''


@pytest.fixture
def data(tmp_path, monkeypatch):
    (tmp_path / "ds_plug.py").write_text(PLUG)
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop("ds_plug", None)
    root = tmp_path / "data"
    for name in ("a", "b"):
        write_static_sequence(root / name, n_cycles=3, shape=(32, 48))
    yield root
    sys.modules.pop("ds_plug", None)


def _run(data, out, methods):
    return main(["run", str(data), "--sequences", "all", "--scheduler", "serial", "--methods", methods,
                 "-o", str(out), "--no-progress"])


def test_import_path_plugin_is_listed_under_its_run_name(data, tmp_path):
    out = tmp_path / "out"
    assert _run(data, out, "classical-50,ds_plug:Steady") == 0
    results = json.loads((out / "results.json").read_text())
    assert results["methods"] == ["classical-50", "steady"]
    assert results["method_specs"] == {"steady": "ds_plug:Steady"}
    assert results["per_method"]["steady"]["sequences"] == 2 and results["per_method"]["steady"]["cycles"] == 6
    assert results["failed_methods"] == {}
    assert "| steady | 2 | 6 |" in (out / "report.md").read_text()


def test_a_plugin_failing_in_every_unit_is_named_and_the_exit_code_is_1(data, tmp_path, capsys):
    out = tmp_path / "out"
    assert _run(data, out, "classical-50,ds_plug:Broken") == 1
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if "no imu/imu.csv" not in ln]
    assert len(err) == 1 and "1 method(s) failed in every unit" in err[0] and "broken" in err[0]
    results = json.loads((out / "results.json").read_text())
    assert results["failed_methods"] == {"broken": "failed: raised RuntimeError: always at cycle 0"}
    assert results["per_method"]["classical-50"]["cycles"] == 6  # the others are kept
    report = (out / "report.md").read_text()
    assert "Methods that failed in every unit: 1" in report and "- broken: failed: raised RuntimeError" in report


SLOW = '''
import time


class Slow:
    name = "slow"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        time.sleep(0.4)
        return 5.0
'''


def test_a_concurrent_resume_is_refused_and_leaves_the_live_run_whole(tmp_path, capsys, monkeypatch):
    import os
    import subprocess
    import time

    (tmp_path / "slow_plug.py").write_text(SLOW)
    monkeypatch.syspath_prepend(str(tmp_path))
    root = tmp_path / "data"
    for name in ("a", "b"):
        write_static_sequence(root / name, n_cycles=4, shape=(32, 48))
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])}
    live = subprocess.Popen([sys.executable, "-m", "emulator.commands.cli", "run", str(root), "--sequences", "all",
                             "--scheduler", "serial", "--methods", "slow_plug:Slow", "-o", str(out), "--no-progress"],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60
        while not any(p.name.startswith(".") for d in out.glob("*") if d.is_dir() for p in d.iterdir()):
            assert time.monotonic() < deadline and live.poll() is None, "the live run never staged a unit"
            time.sleep(0.05)
        staging = [p for d in out.glob("*") if d.is_dir() for p in d.iterdir() if p.name.startswith(".")]
        rc = main(["run", str(root), "--sequences", "all", "--scheduler", "serial", "--methods", "slow_plug:Slow",
                   "-o", str(out), "--resume", "--no-progress"])
        err = [ln for ln in capsys.readouterr().err.strip().splitlines() if "no imu/imu.csv" not in ln]
        assert rc == 1 and len(err) == 1 and "being written by another process" in err[0] and str(out) in err[0]
        assert all(p.exists() for p in staging if live.poll() is None)
    finally:
        stdout, stderr = live.communicate(timeout=120)
    assert live.returncode == 0, stderr
    results = json.loads((out / "results.json").read_text())
    assert results["errors"] == [] and results["per_method"]["slow"]["cycles"] == 8
    assert not (out / "run.lock").exists()


def test_a_plugin_calling_sys_exit_does_not_stop_a_serial_dataset_run(data, tmp_path, capsys):
    out = tmp_path / "out"
    assert _run(data, out, "classical-50,ds_plug:Exits") == 1
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if "no imu/imu.csv" not in ln]
    assert len(err) == 1 and "exits: failed: called sys.exit(0) at cycle 0" in err[0]
    results = json.loads((out / "results.json").read_text())
    assert [u["sequence"] for u in results["units"]] == ["a", "b"]  # both units ran to the end
    assert results["per_method"]["classical-50"]["cycles"] == 6
