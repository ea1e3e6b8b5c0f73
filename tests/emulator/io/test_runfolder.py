"""Faults of the run folder and of ``exposim run`` found by trying bad input (issue 11).

The lock against a second writer (a real process holding it), a stale lock after SIGKILL,
a corrupt run.json on --resume, bad arguments that must leave nothing behind, and
--initial-ms outside --range-ms.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from emulator.commands.cli import main
from emulator.errors import RunLockedError
from emulator.io.runfolder import LOCK_FILE, RunLock
from tests.emulator.playback.test_playback import write_static_sequence

METHODS = "classical-50,fixed"
#: Holds the lock of argv[1] and prints its PID, then waits until stdin closes (or it is killed).
HOLDER = (
    "import sys\n"
    "from emulator.io.runfolder import RunLock\n"
    "lock = RunLock.acquire(sys.argv[1])\n"
    "print(lock.owner['pid'], flush=True)\n"
    "sys.stdin.read()\n"
    "lock.release()\n"
)


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("rf") / "seq", n_cycles=5, shape=(16, 24))
    return root


def _run(seq, out, *extra):
    return main(["run", str(seq), "--methods", METHODS, "-o", str(out), "--no-progress", *extra])


def _csv(out, name="classical-50"):
    return (out / name / "exposures.csv").read_text()


def _hold(run_dir):
    """Start a real process that holds the lock of ``run_dir``; returns (process, its pid)."""
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(run_dir)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    pid = int(proc.stdout.readline())
    assert pid == proc.pid
    return proc, pid


def _one_error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_resume_while_the_run_is_live_is_refused(seq, tmp_path, capsys):
    out = tmp_path / "run"
    assert _run(seq, out) == 0
    before = {m: _csv(out, m) for m in METHODS.split(",")}
    proc, pid = _hold(out)
    try:
        capsys.readouterr()
        assert _run(seq, out, "--resume") == 1
        line = _one_error_line(capsys.readouterr().err)
        assert str(out) in line and f"pid {pid}" in line and "being written by another process" in line
        assert {m: _csv(out, m) for m in METHODS.split(",")} == before  # no doubled rows
        with pytest.raises(RunLockedError, match=f"pid {pid}"):
            RunLock.acquire(out)
    finally:
        proc.stdin.close()
        assert proc.wait(timeout=30) == 0
    assert not (out / LOCK_FILE).exists()  # released by its holder
    assert _run(seq, out, "--resume") == 0
    assert {m: _csv(out, m) for m in METHODS.split(",")} == before


@pytest.mark.slow
def test_stale_lock_after_sigkill_is_taken_over_and_the_run_resumes(seq, tmp_path):
    full = tmp_path / "full"
    assert _run(seq, full) == 0
    out = tmp_path / "run"
    assert _run(seq, out) == 0
    # Make it look interrupted: status running, two rows of each CSV gone, a writer killed.
    info = json.loads((out / "run.json").read_text())
    info.update(status="running", cycles_done=3)
    (out / "run.json").write_text(json.dumps(info))
    for m in METHODS.split(","):
        lines = _csv(out, m).splitlines(keepends=True)
        (out / m / "exposures.csv").write_text("".join(lines[:-2]))
    proc, pid = _hold(out)
    os.kill(pid, signal.SIGKILL)
    proc.wait(timeout=30)
    proc.stdin.close()
    proc.stdout.close()
    owner = json.loads((out / LOCK_FILE).read_text())
    assert owner["pid"] == pid  # the lock file stays behind, naming a dead process
    assert _run(seq, out, "--resume") == 0
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "complete" and info["cycles_done"] == 5
    assert [s["pid"] for s in info["stale_locks"]] == [pid]
    for m in METHODS.split(","):
        assert _csv(out, m) == _csv(full, m)  # every row exactly once
    assert not (out / LOCK_FILE).exists()


def test_stale_lock_with_a_dead_pid_on_this_host(seq, tmp_path):
    """A lock file written by hand (no flock held) whose PID does not exist is stale."""
    import socket

    out = tmp_path / "run"
    assert _run(seq, out) == 0
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (out / LOCK_FILE).write_text(json.dumps({"pid": dead.pid, "host": socket.gethostname(), "started": "x"}))
    lock = RunLock.acquire(out)
    try:
        assert lock.stale_owner["pid"] == dead.pid and lock.owner["pid"] == os.getpid()
    finally:
        lock.release()
    # a hand-written lock naming a live process on this host (it has not flocked yet) is not stale
    (out / LOCK_FILE).write_text(json.dumps({"pid": os.getppid(), "host": socket.gethostname()}))
    with pytest.raises(RunLockedError, match=f"pid {os.getppid()}"):
        RunLock.acquire(out)


def test_corrupt_run_json_on_resume_is_one_line(seq, tmp_path, capsys):
    out = tmp_path / "run"
    assert _run(seq, out) == 0
    (out / "run.json").write_text('{"methods": [')
    capsys.readouterr()
    assert _run(seq, out, "--resume") == 1
    line = _one_error_line(capsys.readouterr().err)
    assert line.startswith("exposim run: error: ") and f"{out / 'run.json'}: malformed JSON" in line
    assert not (out / LOCK_FILE).exists()  # the lock was released
    (out / "run.json").write_text("[1, 2]")
    assert _run(seq, out, "--resume") == 1
    assert "expected a JSON object" in _one_error_line(capsys.readouterr().err)


@pytest.mark.parametrize("bad", [
    ["--initial-ms", "-1"], ["--initial-ms", "nan"], ["--initial-ms", "inf"], ["--initial-ms", "0"],
    ["--jobs", "0"], ["--jobs", "-2"], ["--range-ms", "10", "1"], ["--range-ms", "0", "5"],
    ["--range-ms", "nan", "5"], ["--range-ms", "1", "inf"], ["--noise-seed", "-1"],
    ["--noise-model", "x.json"], ["--noise", "consistent"], ["--methods", "classical-50,nope"],
])
def test_bad_arguments_leave_nothing_behind(seq, tmp_path, capsys, bad):
    out = tmp_path / "run"
    args = ["run", str(seq), "-o", str(out), "--no-progress", *bad]
    if "--methods" not in bad:
        args += ["--methods", "classical-50"]
    assert main(args) == 1
    line = _one_error_line(capsys.readouterr().err)
    assert line.startswith("exposim run: error: ")
    assert not out.exists(), sorted(out.rglob("*"))
    # a corrected re-run then works
    assert main(["run", str(seq), "-o", str(out), "--no-progress", "--methods", "classical-50"]) == 0
    assert json.loads((out / "run.json").read_text())["status"] == "complete"


def test_bad_argument_names_its_flag(seq, tmp_path, capsys):
    for bad, flag in ((["--initial-ms", "nan"], "--initial-ms nan"), (["--jobs", "0"], "--jobs 0"),
                      (["--range-ms", "10", "1"], "--range-ms 10.0 1.0")):
        assert main(["run", str(seq), "-o", str(tmp_path / "r"), "--no-progress", *bad]) == 1
        assert flag in capsys.readouterr().err


def test_initial_ms_is_clamped_to_the_range(seq, tmp_path, capsys):
    out = tmp_path / "run"
    assert _run(seq, out, "--initial-ms", "1e9", "--range-ms", "0.5", "20") == 0
    err = capsys.readouterr().err
    assert "warning: --initial-ms 1e+09 is outside --range-ms 0.5 20; clamped to 20 ms" in err
    info = json.loads((out / "run.json").read_text())
    assert info["initial_ms"] == 1e9 and info["initial_ms_clamped"] == 20.0 and "clamped to 20 ms" in info["warnings"][0]
    for m in METHODS.split(","):
        first = _csv(out, m).splitlines()[1].split(",")
        assert float(first[2]) == 20.0  # target_ms of cycle 0
    # resuming with the same (unclamped) argument is the same configuration
    assert _run(seq, out, "--resume") == 0
    low = tmp_path / "low"
    assert _run(seq, low, "--initial-ms", "0.001") == 0
    assert float(_csv(low).splitlines()[1].split(",")[2]) == 0.02  # the default range's floor


def test_ctrl_c_stops_cleanly_with_130_and_the_run_resumes(seq, tmp_path, capsys, monkeypatch):
    from emulator.io import runfolder

    full = tmp_path / "full"
    assert _run(seq, full) == 0
    out = tmp_path / "run"
    real = runfolder.RunWriter.append_row
    rows = []

    def interrupted_after_three(self, method, row):
        if len(rows) == 3:
            raise KeyboardInterrupt
        rows.append(row)
        real(self, method, row)

    monkeypatch.setattr(runfolder.RunWriter, "append_row", interrupted_after_three)
    capsys.readouterr()
    assert _run(seq, out) == 130
    assert _one_error_line(capsys.readouterr().err) == "exposim run: interrupted"
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "interrupted" and info["cycles_done"] == 1
    assert not (out / LOCK_FILE).exists()
    monkeypatch.setattr(runfolder.RunWriter, "append_row", real)
    assert _run(seq, out, "--resume") == 0
    for m in METHODS.split(","):
        assert _csv(out, m) == _csv(full, m)


def test_os_errors_are_one_line_naming_the_path(seq, tmp_path, capsys, monkeypatch):
    from emulator.io import borealhdr

    real = borealhdr.FolderSource.read_bytes

    def denied(self, path):  # an unreadable PNG
        if str(path).endswith(".png"):
            raise PermissionError(13, "Permission denied", str(path))
        return real(self, path)

    monkeypatch.setattr(borealhdr.FolderSource, "read_bytes", denied)
    out = tmp_path / "run"
    assert _run(seq, out) == 1
    line = _one_error_line(capsys.readouterr().err)
    assert line.startswith("exposim run: error: ") and line.endswith(".png: Permission denied") and str(seq) in line
    monkeypatch.undo()
    if os.geteuid() != 0:  # root reads and writes anything: a real read-only folder only bites others
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        try:
            assert _run(seq, ro / "run") == 1
            assert "Permission denied" in _one_error_line(capsys.readouterr().err)
        finally:
            ro.chmod(0o700)


def test_info_into_a_closed_pipe_is_quiet(tmp_path):
    exe = os.path.join(os.path.dirname(sys.executable), "exposim")
    if not os.path.exists(exe):
        pytest.skip("no exposim script beside the interpreter")
    # 600 cycles: `info --json` writes > 128 KiB, more than the pipe holds, so the write after
    # `head` has gone fails with EPIPE
    from emulator.io.png import encode_png

    root = tmp_path / "long"
    png = encode_png(np.zeros((2, 2), np.uint16))
    for i in range(600 * 6):
        folder = root / "camera_left" / f"{2.0 ** (i % 6):.1f}"
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{1_000_000_000 + 45_000_000 * i}.png").write_bytes(png)
    full = subprocess.run([exe, "info", "--json", str(root)], capture_output=True, text=True, timeout=120)
    assert full.returncode == 0 and len(full.stdout) > 2 * 65536
    proc = subprocess.run(f"'{exe}' info --json '{root}' | head -c 20; echo \" rc=${{PIPESTATUS[0]}}\"",
                          shell=True, executable="/bin/bash", capture_output=True, text=True, timeout=120)
    assert proc.stdout == full.stdout[:20] + " rc=1\n"  # quiet, exit code 1 as for SIGPIPE
    assert proc.stderr == "", proc.stderr
