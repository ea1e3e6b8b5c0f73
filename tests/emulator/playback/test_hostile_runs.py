"""Whole runs under hostile conditions (issue 24), written independently of
tests/test_faults_*.py: Ctrl-C and SIGTERM mid-run, then --resume; hostile plugins in dataset
runs."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from emulator.commands.cli import main
from test_playback import write_static_sequence

HERE = Path(__file__).resolve().parent
MOD = "hostile_plugins"


@pytest.fixture(autouse=True)
def _plugins_importable(monkeypatch):
    monkeypatch.syspath_prepend(str(HERE))


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("hds") / "data"
    for i, name in enumerate(("a", "b")):
        write_static_sequence(root / name, n_cycles=3 + i, shape=(32, 48))
    return root


def _tables(run_dir, names):
    return {n: (run_dir / n / "exposures.csv").read_bytes() for n in names}


def test_ctrl_c_inside_a_method_stops_the_run_and_keeps_a_valid_prefix(dataset, tmp_path):
    """In the run's process (--workers inline) a KeyboardInterrupt during a call is Ctrl-C."""
    seq = dataset / "b"
    methods = f"{MOD}:Interrupt,classical-50"
    clean = tmp_path / "clean"
    out = tmp_path / "run"
    try:
        rc = main(["run", str(seq), "--methods", methods, "-o", str(out), "-q", "--workers", "inline"])
    except KeyboardInterrupt:
        rc = 130
    assert rc == 130, rc  # Ctrl-C stops the run: it is not one method's failure
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "interrupted", info["status"]
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(clean), "-q"]) == 0
    # the plugin interrupts again on resume (its third call in this process is a new object's),
    # so resume only classical-50's share: the table it has is a prefix of the clean one
    got = (out / "classical-50" / "exposures.csv").read_bytes()
    assert (clean / "classical-50" / "exposures.csv").read_bytes().startswith(got)


def test_keyboard_interrupt_raised_by_a_method_in_its_worker_is_its_own_failure(dataset, tmp_path):
    """A worker never receives the terminal's Ctrl-C (it runs in its own session), so a
    KeyboardInterrupt there is the method's own doing: it fails alone, named, and the run completes."""
    seq = dataset / "b"
    clean, out = tmp_path / "clean", tmp_path / "run"
    assert main(["run", str(seq), "--methods", f"{MOD}:Interrupt,classical-50", "-o", str(out), "-q"]) == 0
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(clean), "-q"]) == 0
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "complete"
    assert info["method_status"]["h-interrupt"] == "failed: raised KeyboardInterrupt:  at cycle 2"
    assert (out / "classical-50" / "exposures.csv").read_bytes() == (clean / "classical-50" / "exposures.csv").read_bytes()


def test_sigterm_marks_the_run_interrupted_and_resume_gives_the_clean_bytes(dataset, tmp_path):
    seq = dataset / "b"
    methods = f"{MOD}:Sleepy,classical-50"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
    clean = tmp_path / "clean"
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "emulator.commands.cli", "run", str(seq), "--methods", methods,
                             "-o", str(out), "-q"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while time.time() < deadline:  # wait until the first row is written
        p = out / "classical-50" / "exposures.csv"
        if p.is_file() and p.read_text().count("\n") >= 2:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode in (143, -signal.SIGTERM, 1), (proc.returncode, err)
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "interrupted", (info["status"], err)
    assert "Traceback" not in err, err
    assert not (out / "run.lock").exists()
    rc = subprocess.run([sys.executable, "-m", "emulator.commands.cli", "run", str(seq), "-o", str(out), "--resume", "-q"],
                        env=env, capture_output=True, text=True, timeout=120)
    assert rc.returncode == 0, rc.stderr
    assert main(["run", str(seq), "--methods", methods, "-o", str(clean), "-q"]) == 0
    assert _tables(out, ["classical-50", "h-sleepy"]) == _tables(clean, ["classical-50", "h-sleepy"])


def test_dataset_run_names_an_import_path_plugin_and_its_failures(dataset, tmp_path, capsys):
    out = tmp_path / "ds"
    rc = main(["run", str(dataset), "--sequences", "all", "--scheduler", "serial", "--methods",
               f"{MOD}:Exit0,{MOD}:TryAllWritesQuietly,classical-50", "-o", str(out), "-q"])
    results = json.loads((out / "results.json").read_text())
    # the plugin that ran is listed under the name it ran under, with its sequences and cycles counted
    assert results["per_method"]["h-quiet"]["sequences"] == 2 and results["per_method"]["h-quiet"]["cycles"] == 7
    assert results["method_specs"]["h-quiet"] == f"{MOD}:TryAllWritesQuietly"
    # a method that failed in every unit is named as failed, and the run says so in its exit code
    assert "sys.exit(0)" in results["failed_methods"]["h-exit0"]
    assert "h-exit0" in (out / "report.md").read_text()
    assert rc == 1
    err = capsys.readouterr().err
    assert "h-exit0" in err
    for name in ("a", "b"):
        (table,) = (out / name).glob("*/classical-50/exposures.csv")
        single = tmp_path / f"single-{name}"
        assert main(["run", str(dataset / name), "--methods", "classical-50", "-o", str(single), "-q"]) == 0
        assert table.read_bytes() == (single / "classical-50" / "exposures.csv").read_bytes()


def _snapshot(root):
    return {p.relative_to(root).as_posix(): (p.read_bytes() if p.is_file() else None)
            for p in sorted(root.rglob("*")) if p.name != "run.lock"}


def test_a_resume_while_another_process_holds_the_dataset_lock_changes_nothing(dataset, tmp_path, capsys):
    out = tmp_path / "ds"
    common = ["run", str(dataset), "--sequences", "all", "--scheduler", "serial", "--methods", "classical-50",
              "-o", str(out), "-q"]
    assert main(common) == 0
    # a stale-looking staging folder the live run would own
    staging = out / ".staging-live"
    staging.mkdir()
    (staging / "keep.txt").write_text("live")
    before = _snapshot(out)
    holder = subprocess.Popen([sys.executable, "-c",
                               "import sys, time; from emulator.io.runfolder import RunLock; "
                               f"lock = RunLock.acquire({str(out)!r}); print('held', flush=True); time.sleep(60)"],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        capsys.readouterr()
        assert main([*common, "--resume"]) == 1
        err = capsys.readouterr().err.strip()
        lines = [x for x in err.splitlines() if "warning" not in x]
        assert len(lines) == 1 and str(out) in lines[0], err
        assert _snapshot(out) == before
    finally:
        holder.kill()
        holder.wait()
