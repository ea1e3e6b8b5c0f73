"""Faults of method workers and whole runs: a method that forks, hangs, dies or is interrupted, and Ctrl-C or SIGTERM mid-run, change no other method's results and leave a run that resumes (two suites written independently, one after the other).

Fault suite, issue 34 (method workers): a method that forks, patches a library, never returns,
leaves a thread running or kills its own process cannot change the other methods' results nor
keep the run from ending; it fails alone, named, and the run exits within its time limit.

Every case runs the hostile plugin between built-in methods and compares the built-ins' CSV
bytes with a run without it.  Runs that could hang go through a subprocess with a timeout (a
hang fails the test instead of stalling the suite).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from emulator.commands.cli import main
from emulator.playback import run
from tests.emulator.playback.test_playback import write_static_sequence
from pathlib import Path

HOSTILE = '''
import os, threading, time
import cv2
import numpy as np


class _Base:
    name = None

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        self.act(raw, exposure_ms)
        return float(exposure_ms) * 1.25

    def act(self, raw, t):
        pass


class Forker(_Base):
    name = "forker"

    def act(self, raw, t):
        os.fork()  # the child would go on running the loop


class PatchSobel(_Base):
    """Wraps cv2.Sobel to halve its output once, on its first call."""
    name = "patch-sobel"

    def act(self, raw, t):
        if getattr(cv2.Sobel, "patched", False):
            return
        real, calls = cv2.Sobel, []

        def half(*a, **k):
            calls.append(1)
            out = real(*a, **k)
            return out / 2 if len(calls) == 1 else out
        half.patched = True
        cv2.Sobel = half


class PatchMean(_Base):
    name = "patch-mean"

    def act(self, raw, t):
        real = np.mean
        np.mean = lambda *a, **k: real(*a, **k) * 1.5
        np.average = np.mean
        np.sum = lambda *a, **k: 0


class Sleeper(_Base):
    name = "sleeper"

    def act(self, raw, t):
        time.sleep(10 ** 6)


class Threader(_Base):
    name = "threader"

    def act(self, raw, t):
        threading.Thread(target=time.sleep, args=(10 ** 6,), name="plugin-sleeper").start()


class InitThreader(_Base):
    name = "init-threader"

    def __init__(self):
        threading.Thread(target=time.sleep, args=(10 ** 6,), name="init-sleeper").start()


class Dier(_Base):
    name = "dier"

    def act(self, raw, t):
        os._exit(3)


class ServerKill(_Base):
    """Kills the process that started the workers (the fork server), not itself."""
    name = "server-kill"
    done = False

    def act(self, raw, t):
        if not ServerKill.done:  # once: afterwards the parent is another process
            ServerKill.done = True
            os.kill(os.getppid(), 9)


class PidSleeper(_Base):
    name = "pid-sleeper"

    def act(self, raw, t):
        with open(os.environ["HOSTILE_PID_FILE"], "w") as fh:
            fh.write(str(os.getpid()))
        time.sleep(10 ** 6)


class SelfKill(_Base):
    name = "self-kill"

    def act(self, raw, t):
        os.kill(os.getpid(), 9)
'''

BUILTINS = "classical-50,shim,zhang"
N_CYCLES = 5


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("workers") / "seq", n_cycles=N_CYCLES, shape=(32, 48))
    return root


@pytest.fixture(scope="module")
def alone(seq, tmp_path_factory):
    """The built-ins' CSV bytes without any hostile plugin."""
    out = tmp_path_factory.mktemp("alone") / "run"
    assert main(["run", str(seq), "--methods", BUILTINS, "-o", str(out), "--no-progress"]) == 0
    return {m: (out / m / "exposures.csv").read_bytes() for m in BUILTINS.split(",")}


@pytest.fixture(scope="module")
def plugin_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("plugins")
    (d / "hostile_workers.py").write_text(HOSTILE)
    return d


def _cli(seq, plugin_dir, out, plugin, *extra, timeout=120):
    """The run in a subprocess (PYTHONPATH: the plugin's folder); returns (rc, wall s, stderr)."""
    a, b, c = BUILTINS.split(",")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(plugin_dir), os.environ.get("PYTHONPATH", "")])}
    cmd = [sys.executable, "-m", "emulator.commands.cli", "run", str(seq), "--methods", f"{a},{b},hostile_workers:{plugin},{c}",
           "-o", str(out), "--no-progress", *extra]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout)
    return proc.returncode, time.monotonic() - t0, proc.stderr


def _assert_alone_failed(out, alone, name, why):
    for m, data in alone.items():
        assert (out / m / "exposures.csv").read_bytes() == data, m
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "complete"
    assert info["method_status"][name] == why
    assert all(info["method_status"][m] == "ok" for m in alone)
    assert json.loads((out / "results.json").read_text())["methods"][name]["status"] == why
    return info


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_a_method_that_forks_fails_alone_and_no_child_writes_anything(seq, alone, plugin_dir, tmp_path, jobs):
    out = tmp_path / "run"
    rc, _, err = _cli(seq, plugin_dir, out, "Forker", "--jobs", jobs)
    assert rc == 0, err
    _assert_alone_failed(out, alone, "forker", "failed: forked a child process (os.fork) in next_exposure; its process "
                                               "was stopped at cycle 0")
    time.sleep(0.5)  # a forked child still running the loop would append rows by now
    for m in BUILTINS.split(","):
        assert (out / m / "exposures.csv").read_text().count("\n") == N_CYCLES + 1


@pytest.mark.parametrize("plugin,name", [("PatchSobel", "patch-sobel"), ("PatchMean", "patch-mean")])
def test_a_method_that_patches_a_library_changes_only_itself(seq, alone, plugin_dir, tmp_path, plugin, name):
    """The patch lives in the plugin's own process: shim (cv2.Sobel, np.mean) keeps its bytes, and
    the report after the run is not affected either."""
    out = tmp_path / "run"
    rc, _, err = _cli(seq, plugin_dir, out, plugin)
    assert rc == 0, err
    _assert_alone_failed(out, alone, name, "ok")
    assert (out / "report.md").is_file() and (out / "exposure.png").is_file()


def test_a_method_that_never_returns_is_stopped_at_the_time_limit(seq, alone, plugin_dir, tmp_path):
    out = tmp_path / "run"
    rc, wall, err = _cli(seq, plugin_dir, out, "Sleeper", "--method-timeout-s", "2", timeout=100)
    assert rc == 0, err
    info = _assert_alone_failed(out, alone, "sleeper", "failed: did not return within the limit of 2 s "
                                                       "(--method-timeout-s); its process was stopped at cycle 0")
    assert info["method_timeout_applied_s"] == 2.0 and info["workers"] == "process"


def test_the_default_time_limit_is_recorded(seq, tmp_path):
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "fixed", "-o", str(out), "--no-progress"]) == 0
    info = json.loads((out / "run.json").read_text())
    assert info["method_timeout_s"] is None and info["method_timeout_applied_s"] == 120.0
    assert info["workers"] == "process"
    inline = tmp_path / "inline"
    assert main(["run", str(seq), "--methods", "fixed", "-o", str(inline), "--no-progress", "--workers", "inline"]) == 0
    info = json.loads((inline / "run.json").read_text())
    assert info["workers"] == "inline" and info["method_timeout_applied_s"] is None


@pytest.mark.parametrize("plugin,name,why", [
    ("Threader", "threader", "failed: left 1 thread running in next_exposure (plugin-sleeper); its process was stopped "
                             "at cycle 0"),
    ("InitThreader", "init-threader", "failed: left 1 thread running after it was built (init-sleeper); its process "
                                      "was stopped at cycle 0"),
])
def test_a_method_that_leaves_a_thread_running_fails_and_the_command_exits(seq, alone, plugin_dir, tmp_path, plugin,
                                                                           name, why):
    out = tmp_path / "run"
    rc, _, err = _cli(seq, plugin_dir, out, plugin, timeout=100)  # a thread keeping the process alive: timeout
    assert rc == 0, err
    _assert_alone_failed(out, alone, name, why)


@pytest.mark.parametrize("plugin,name,why", [
    ("Dier", "dier", "failed: its process exited with status 3 in next_exposure at cycle 0"),
    ("SelfKill", "self-kill", "failed: its process was killed by SIGKILL in next_exposure at cycle 0"),
    ("ServerKill", "server-kill", "ok"),
])
def test_a_method_whose_process_dies_fails_alone(seq, alone, plugin_dir, tmp_path, plugin, name, why):
    out = tmp_path / "run"
    rc, _, err = _cli(seq, plugin_dir, out, plugin, "--jobs", "2")
    assert rc == 0, err
    _assert_alone_failed(out, alone, name, why)


def test_tables_are_the_same_for_any_jobs_and_inline(seq, tmp_path):
    tables = []
    for extra in (["--jobs", "1"], ["--jobs", "2"], ["--jobs", "4"], ["--workers", "inline"]):
        out = tmp_path / "-".join(extra).strip("-")
        assert main(["run", str(seq), "--methods", "all", "-o", str(out), "--no-progress", *extra]) == 0
        tables.append({p.parent.name: p.read_bytes() for p in sorted(out.glob("*/exposures.csv"))})
    assert len(tables[0]) == 7 and all(t == tables[0] for t in tables[1:])


def test_a_local_class_is_refused_in_one_line_unless_inline(seq):
    class Local:
        name = "local"

        def next_exposure(self, raw, t):
            return 5.0

    with pytest.raises(Exception, match=r"AE method 'local' cannot be handed to a worker process .*--isolation inline"):
        run(seq, [Local()])
    assert len(run(seq, [Local()], workers="inline").steps["local"]) == N_CYCLES


@pytest.mark.parametrize("sig,rc", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_while_a_method_hangs_ends_the_run_at_once(seq, plugin_dir, tmp_path, sig, rc):
    """The method never returns and no limit is near: the signal alone ends the run, in seconds."""
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(plugin_dir), os.environ.get("PYTHONPATH", "")])}
    cmd = [sys.executable, "-m", "emulator.commands.cli", "run", str(seq), "--methods", "classical-50,hostile_workers:Sleeper",
           "-o", str(out), "--no-progress", "--jobs", "2"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    csv = out / "classical-50" / "exposures.csv"  # its header: the loop has started
    deadline = time.monotonic() + 90
    while not csv.is_file():
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.05)
    time.sleep(1.0)  # the sleeper is in its first call (no row is written while cycle 0 waits for it)
    assert proc.poll() is None
    proc.send_signal(sig)
    proc.communicate(timeout=30)
    assert proc.returncode == rc
    assert json.loads((out / "run.json").read_text())["status"] == "interrupted"


STUCK = '''
import signal, sys, time
from pathlib import Path
from emulator.orchestration.interrupts import remove_at_forced_exit, watchdog

staging = Path(sys.argv[1])
staging.mkdir()
remove_at_forced_exit(staging)
for sig in (signal.SIGINT, signal.SIGTERM):  # as native code that swallows the signal
    signal.signal(sig, lambda *a: None)
with watchdog(lambda: "exposim stuck", grace_s=1.0):
    print("ready", flush=True)
    while True:
        time.sleep(0.05)
'''


@pytest.mark.parametrize("sig,rc,what", [(signal.SIGINT, 130, "interrupted"),
                                         (signal.SIGTERM, 143, "terminated (SIGTERM)")])
def test_a_command_stuck_after_a_signal_is_ended_and_leaves_no_staging_folder(tmp_path, sig, rc, what):
    script = tmp_path / "stuck.py"
    script.write_text(STUCK)
    staging = tmp_path / ".walk.partial-x"
    proc = subprocess.Popen([sys.executable, str(script), str(staging)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    assert proc.stdout.readline() == "ready\n"
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == rc
    assert err.strip().splitlines()[-1] == f"exposim stuck: {what}; ended 1 s after the signal"
    assert not staging.exists()


def test_interrupts_end_runs_while_cpu_bound_work_runs_beside_them(seq, plugin_dir, tmp_path):
    """Both cores busy with other work: SIGINT still ends a run (a method hanging in its worker) at once."""
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        test_a_signal_while_a_method_hangs_ends_the_run_at_once(seq, plugin_dir, tmp_path, signal.SIGINT, 130)
    finally:
        for b in burners:
            b.kill()
            b.wait()


def test_a_worker_hanging_in_a_call_ends_when_the_run_is_killed(seq, plugin_dir, tmp_path):
    pid_file = tmp_path / "pid"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(plugin_dir), os.environ.get("PYTHONPATH", "")]),
           "HOSTILE_PID_FILE": str(pid_file)}
    cmd = [sys.executable, "-m", "emulator.commands.cli", "run", str(seq), "--methods", "hostile_workers:PidSleeper",
           "-o", str(tmp_path / "run"), "--no-progress"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 90
    while not (pid_file.is_file() and pid_file.read_text()):
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.05)
    worker = int(pid_file.read_text())
    proc.kill()  # no cleanup in the run: the worker must notice by itself
    proc.wait()
    deadline = time.monotonic() + 30
    while os.path.exists(f"/proc/{worker}") and "zombie" not in _state(worker):
        assert time.monotonic() < deadline, "the worker outlived the run"
        time.sleep(0.1)


def _state(pid: int) -> str:
    try:
        return open(f"/proc/{pid}/status").read().split("State:")[1].split("\n")[0].lower()
    except (OSError, IndexError):
        return "zombie"


# ------------------------------------------------------------------------------------------------
# Whole runs under hostile conditions (issue 24), written independently of the suite above:
# Ctrl-C and SIGTERM mid-run, then --resume; hostile plugins in dataset
# runs.
# ------------------------------------------------------------------------------------------------
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
