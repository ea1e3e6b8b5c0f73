"""Fault suite, issue 45 (the worker boundary, bounded inputs): a full ``/dev/shm`` is said in one line
and the run goes on through pipes with the same bytes; a run's process that dies still leaves
``run.json`` at ``failed``, no lock and no shared memory; nothing a worker sends is unpickled and no
plugin module is imported in the run's process; numeric flags and plugin names are bounded; a
process a plugin leaves running fails it, named; messages name the right thing.

Runs that could hang or kill their own process go through a subprocess with a timeout.  Each case
that adds a plugin compares the built-ins' CSV bytes with a run without it.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from emulator.commands.cli import main
from tests.emulator.playback.test_workers_faults import BUILTINS, alone  # noqa: F401 - the built-ins' bytes without a plugin, on this seq
from tests.emulator.playback.test_playback import write_static_sequence

REPO = Path(__file__).resolve().parents[3]

PLUGINS = '''
import enum, os, signal


class KillRun:
    """At its third call sends SIGBUS to the run's process (the fork server's parent), as a full
    /dev/shm did before blocks were reserved."""
    name = "kill-run"

    def __init__(self):
        self.n = 0

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        self.n += 1
        if self.n == 3:
            with open(f"/proc/{os.getppid()}/stat") as fh:
                run = int(fh.read().rsplit(")", 1)[1].split()[1])
            os.kill(run, signal.SIGBUS)
        return float(exposure_ms)


MARK = os.environ.get("BOUNDARY_MARK", "/nonexistent/mark")


class Color(str, enum.Enum):
    RED = "red"


class Level(enum.IntEnum):
    ONE = 1


class Proposal(float):
    pass


class Evil:
    \"\"\"Unpickled, it would create MARK in the process that unpickles it.\"\"\"
    def __reduce__(self):
        return (open, (MARK, "w"))


class Thing:
    pass


class PluginError(Exception):
    pass


class DataEverywhere:
    \"\"\"Its own classes in every channel back to the run: name, config, answer, guard count, output.\"\"\"
    name = Color.RED

    def __init__(self):
        self.n = 0

    @property
    def guard_count(self):
        return Level.ONE

    def config(self):
        import numpy as np
        return {"color": Color.RED, "evil": Evil(), "thing": Thing(), 3: (1, 2.5), "level": Level.ONE,
                "scalar": np.float64(0.5), Color.RED: np.arange(3), "long": list(range(10 ** 6))}

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        self.n += 1
        print(Color.RED, Evil())
        if self.n == 3:
            raise PluginError(Color.RED)
        return Proposal(exposure_ms * 1.1)


class LongName(DataEverywhere):
    name = "n" * 300


class LeavesProcess(DataEverywhere):
    \"\"\"Starts a process that would outlive the call (and another that leaves its session).\"\"\"
    name = "leaves-process"

    def next_exposure(self, raw, exposure_ms):
        import subprocess
        subprocess.Popen(["sleep", "1000"])
        subprocess.Popen(["sleep", "1001"], start_new_session=True)
        return float(exposure_ms)


class Waits(DataEverywhere):
    \"\"\"A subprocess that finishes within the call: allowed.\"\"\"
    name = "waits"

    def next_exposure(self, raw, exposure_ms):
        import subprocess
        subprocess.run(["true"], check=True)
        return float(exposure_ms)


class Preexec(DataEverywhere):
    name = "preexec"

    def next_exposure(self, raw, exposure_ms):
        import subprocess
        subprocess.run(["sh", "-c", "touch " + MARK], preexec_fn=lambda: None)
        return float(exposure_ms)


class ExitsWhenBuilt(DataEverywhere):
    name = "exits-when-built"

    def __init__(self):
        os._exit(3)


class KillSiblings(DataEverywhere):
    \"\"\"At its second call kills every other worker of the run (the fork server's other children).\"\"\"
    name = "kill-siblings"

    def next_exposure(self, raw, exposure_ms):
        self.n += 1
        if self.n == 2:
            for entry in filter(str.isdigit, os.listdir("/proc")):
                try:
                    with open(f"/proc/{entry}/stat") as fh:
                        ppid = int(fh.read().rsplit(")", 1)[1].split()[1])
                except (OSError, ValueError, IndexError):
                    continue
                if ppid == os.getppid() and int(entry) != os.getpid():
                    os.kill(int(entry), signal.SIGKILL)
        return float(exposure_ms)


class Unbuildable:
    name = "unbuildable"

    def __init__(self):
        raise PluginError(Evil())


class RewritesTable:
    """Appends a row to another method's table (BOUNDARY_TABLE) at its first call: what a process of the user can do."""

    def __init__(self):
        self.done = False

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        if not self.done:
            with open(os.environ["BOUNDARY_TABLE"], "a") as fh:
                fh.write("99,1,1.0,1.0,ok\\n")
            self.done = True
        return exposure_ms
'''


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("boundary") / "seq", n_cycles=4, shape=(240, 320))
    return root


@pytest.fixture(scope="module")
def plugin_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("plugins")
    (d / "boundary_plugins.py").write_text(PLUGINS)
    return d


def _env(plugin_dir=None) -> dict:
    paths = [str(REPO)] + ([str(plugin_dir)] if plugin_dir else []) + [os.environ.get("PYTHONPATH", "")]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}


def test_no_room_in_dev_shm_sends_the_images_through_pipes_with_the_same_bytes(seq, alone, tmp_path, monkeypatch,
                                                                                capsys):
    from emulator.playback import workers

    monkeypatch.setattr(workers, "reserve_block", lambda size: None)  # /dev/shm full for every block
    out = tmp_path / "run"
    progress = []
    real = workers.MethodWorker.reserve

    def reserve(self, nbytes):  # the blocks are reserved before any call, i.e. before the first cycle
        progress.append(self._ahead is None and self._shm_box[0] is None)
        return real(self, nbytes)

    monkeypatch.setattr(workers.MethodWorker, "reserve", reserve)
    assert main(["run", str(seq), "--methods", BUILTINS, "-o", str(out), "--no-progress"]) == 0
    assert progress == [True, True, True]
    said = [line for line in capsys.readouterr().err.splitlines() if "/dev/shm" in line]
    assert len(said) == 1 and said[0].startswith("exposim: warning: /dev/shm had no room for the image blocks of 3 of "
                                                 "3 methods (classical-50, shim, zhang; 0.3 MB each, 0.9 MB more needed")
    for m, data in alone.items():
        assert (out / m / "exposures.csv").read_bytes() == data, m
    info = json.loads((out / "run.json").read_text())
    assert info["shared_memory_pipes"] == BUILTINS.split(",")
    assert info["shared_memory"].startswith("/dev/shm had no room for the image blocks of 3 of 3 methods")
    assert "MB more needed" in info["shared_memory"]


def test_a_reserved_block_takes_its_pages_when_made():
    from emulator.playback.shmblock import block_prefix, reserve_block

    shm = reserve_block(1 << 20)
    try:
        assert shm.name.startswith(block_prefix())
        st = os.stat(f"/dev/shm/{shm.name}")
        assert st.st_blocks * 512 >= 1 << 20  # allocated, not a sparse file
    finally:
        shm.close()
        shm.unlink()
    assert reserve_block(1 << 50) is None  # more than any /dev/shm holds: None, no block left behind
    assert not [e for e in os.listdir("/dev/shm") if e.startswith(block_prefix())]


def _small_shm_works() -> str | None:
    if not shutil.which("unshare") or os.geteuid() != 0:
        return "needs root and unshare to mount a small /dev/shm in a private mount namespace"
    probe = subprocess.run(["unshare", "-m", "sh", "-c", "mount -t tmpfs -o size=64m tmpfs /dev/shm"],
                           capture_output=True, text=True)
    return None if probe.returncode == 0 else f"this machine refuses a private /dev/shm mount ({probe.stderr.strip()})"


def test_eight_methods_run_on_dockers_64_mib_dev_shm(sample_seq, tmp_path):
    """The docs' own example, every built-in and the example plugin, on a 64 MiB /dev/shm: 8 blocks
    of up to 9.2 MB do not fit; before reservation the first write raised SIGBUS (rc 135)."""
    why = _small_shm_works()
    if why:
        pytest.skip(why)
    out = tmp_path / "run"
    script = (f"mount -t tmpfs -o size=64m tmpfs /dev/shm && exec {sys.executable} -m emulator.commands.cli run {sample_seq} "
              f"--methods all,my_ae:MyAE -o {out} --no-progress")
    proc = subprocess.run(["unshare", "-m", "sh", "-c", script], env=_env(REPO / "examples"), capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "exposim: warning: /dev/shm had no room for the image blocks of 1 of 8 methods" in proc.stderr
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "complete" and set(info["method_status"].values()) == {"ok"}


def test_a_run_killed_by_a_signal_leaves_run_json_failed_no_lock_and_no_shared_memory(seq, plugin_dir, tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "emulator.commands.cli", "run", str(seq), "--methods",
                           "classical-50,boundary_plugins:KillRun,shim", "-o", str(out), "--no-progress"],
                          env=_env(plugin_dir), capture_output=True, text=True, timeout=120)
    assert proc.returncode == -7 or proc.returncode == 135  # SIGBUS
    info = {}
    for _ in range(200):  # the watcher finishes run.json once it sees the pipe close (at most 10 s here)
        info = json.loads((out / "run.json").read_text())
        if info["status"] != "running" and not (out / "run.lock").exists():
            break
        time.sleep(0.05)
    assert info["status"] == "failed"
    assert info["error"].startswith(f"the run's process (pid {proc_pid(info)}) ended without finishing")
    assert not (out / "run.lock").exists()
    assert not [e for e in os.listdir("/dev/shm") if e.startswith(f"exposim-{proc_pid(info)}-")]


def proc_pid(info: dict) -> int:
    """The run's pid, as ``run.json`` names its writer."""
    return int(info["writer"]["pid"])


def test_nothing_a_worker_sends_is_unpickled_no_plugin_module_is_imported_in_the_run(seq, alone, plugin_dir,
                                                                                       tmp_path, monkeypatch, capsys):
    """The plugin's own classes (a str Enum, an IntEnum, a float subclass, an exception class, an object
    whose __reduce__ writes a file) in its name, config, answers, guard count, error and output: the
    run's process never imports the plugin's module and never runs its code."""
    mark = tmp_path / "unpickled"
    monkeypatch.setenv("BOUNDARY_MARK", str(mark))
    monkeypatch.syspath_prepend(str(plugin_dir))  # the workers find the module; the run must not import it
    a, b, c = BUILTINS.split(",")
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", f"{a},{b},boundary_plugins:DataEverywhere,{c}", "-o", str(out),
                 "--no-progress"]) == 0
    assert "boundary_plugins" not in sys.modules
    assert not mark.exists()
    for m, data in alone.items():
        assert (out / m / "exposures.csv").read_bytes() == data, m
    info = json.loads((out / "run.json").read_text())
    config = info["method_options"]["red"]
    assert config["color"] == "red" and config["3"] == [1, 2.5] and config["level"] == 1 and config["scalar"] == 0.5
    assert config["red"] == "array([0, 1, 2])" and config["long"].startswith("[0, 1, 2,") and len(config["long"]) == 203
    assert config["evil"].startswith("<boundary_plugins.Evil object at") and config["thing"].startswith("<boundary")
    assert info["method_status"]["red"] == "failed: raised PluginError: Color.RED at cycle 2"
    assert (out / "red" / "exposures.csv").read_text().count("\n") == 3  # two cycles, guarded by its count
    assert main(["run", str(seq), "--methods", f"{a},boundary_plugins:Unbuildable", "-o", str(tmp_path / "r2"),
                 "--no-progress"]) == 1
    assert "PluginError" in capsys.readouterr().err
    assert "boundary_plugins" not in sys.modules and not mark.exists()


@pytest.mark.parametrize("flags,said", [
    (["--rate", "native", "--latency-frames", "2000000000"], "--latency-frames 2000000000: latency_frames must be an "
                                                             "integer >= 0, at most 1000000"),
    (["--rate", "native", "--latency-frames", "24"], "latency_frames 24: must be below the recording's frame count "
                                                     "(24 frames at native rate"),
    (["--method-timeout-s", "3e6"], "--method-timeout-s 3000000.0: method_timeout_s must be at most 2147483 s"),
])
def test_numeric_flags_are_bounded_before_they_cost_memory_or_time(seq, tmp_path, capsys, flags, said):
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(out), "--no-progress", *flags]) == 1
    err = capsys.readouterr().err
    assert said in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_a_native_latency_below_the_frame_count_runs(seq, tmp_path):
    assert main(["run", str(seq), "--methods", "classical-50", "-o", str(tmp_path / "run"), "--no-progress",
                 "--rate", "native", "--latency-frames", "23"]) == 0


def test_a_plugin_name_is_bounded_before_its_folder_is_made(seq, plugin_dir, tmp_path, monkeypatch, capsys):
    monkeypatch.syspath_prepend(str(plugin_dir))
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "classical-50,boundary_plugins:LongName", "-o", str(out),
                 "--no-progress"]) == 1
    assert "at most 200 characters" in capsys.readouterr().err
    assert not out.exists()


def _sleepers() -> set[int]:
    found = set()
    for entry in os.listdir("/proc"):
        try:
            cmd = Path(f"/proc/{entry}/cmdline").read_bytes()
        except OSError:
            continue
        if cmd in (b"sleep\x001000\x00", b"sleep\x001001\x00"):
            found.add(int(entry))
    return found


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_a_process_left_running_after_a_call_fails_the_method_named_and_is_ended(seq, alone, plugin_dir, tmp_path,
                                                                               monkeypatch, jobs):
    """subprocess.Popen not waited for (the fork check does not see it): the process could rewrite the
    other workers' image blocks; it is found in /proc after the call, ended, and the method fails."""
    monkeypatch.syspath_prepend(str(plugin_dir))
    before = _sleepers()
    a, b, c = BUILTINS.split(",")
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", f"{a},{b},boundary_plugins:LeavesProcess,boundary_plugins:Waits,{c}",
                 "-o", str(out), "--no-progress", "--jobs", jobs]) == 0
    for m, data in alone.items():
        assert (out / m / "exposures.csv").read_bytes() == data, m
    status = json.loads((out / "run.json").read_text())["method_status"]
    assert status["waits"] == "ok"
    assert status["leaves-process"].startswith("failed: left 2 processes running in next_exposure (pid ")
    assert "leftover_process); they and its process were stopped at cycle 0" in status["leaves-process"]
    assert _sleepers() <= before  # both ended, the one in its own session too


def test_a_subprocess_with_preexec_fn_is_named_as_such(seq, plugin_dir, tmp_path, monkeypatch):
    mark = tmp_path / "ran"
    monkeypatch.setenv("BOUNDARY_MARK", str(mark))
    monkeypatch.syspath_prepend(str(plugin_dir))
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "classical-50,boundary_plugins:Preexec", "-o", str(out),
                 "--no-progress"]) == 0
    status = json.loads((out / "run.json").read_text())["method_status"]["preexec"]
    assert status.startswith("failed: started a subprocess with preexec_fn in next_exposure")
    assert "refused: the command never ran" in status and "os.fork" not in status
    assert not mark.exists()


def test_a_build_that_kills_its_worker_says_built_not_next_exposure(seq, plugin_dir, tmp_path, monkeypatch, capsys):
    monkeypatch.syspath_prepend(str(plugin_dir))
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "classical-50,boundary_plugins:ExitsWhenBuilt", "-o", str(out),
                 "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert ("could not be built: its process exited with status 3 while it was built (its import, factory or "
            "constructor)") in err and "next_exposure" not in err


def test_a_sibling_worker_killed_by_a_plugin_is_reported_as_killed_by_the_signal(seq, plugin_dir, tmp_path,
                                                                                  monkeypatch):
    monkeypatch.syspath_prepend(str(plugin_dir))
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "classical-50,boundary_plugins:KillSiblings,shim", "-o", str(out),
                 "--no-progress"]) == 0
    status = json.loads((out / "run.json").read_text())["method_status"]
    assert status["kill-siblings"] == "ok"
    for name in ("classical-50", "shim"):
        assert status[name].startswith("failed: its process was killed by SIGKILL in next_exposure at cycle "), name


def test_an_ordinary_object_in_config_is_recorded_inline_too(seq, plugin_dir, tmp_path, monkeypatch):
    """--workers inline (no worker between): the object's repr in run.json, the run goes on (it ended with rc 1)."""
    monkeypatch.syspath_prepend(str(plugin_dir))
    out = tmp_path / "run"
    assert main(["run", str(seq), "--methods", "classical-50,boundary_plugins:DataEverywhere", "-o", str(out),
                 "--no-progress", "--workers", "inline"]) == 0
    config = json.loads((out / "run.json").read_text())["method_options"]["red"]
    assert config["thing"].startswith("<boundary_plugins.Thing object at") and config["color"] == "red"
    sys.modules.pop("boundary_plugins", None)


PATCHER = """
import cv2
_real = cv2.cvtColor
cv2.cvtColor = lambda *a, **k: _real(*a, **k) // 2  # at import: every gray image of the process it runs in


class PatchAE:
    name = "patch-ae"

    def reset(self):
        pass

    def next_exposure(self, raw, exposure_ms):
        return float(exposure_ms)
"""


def test_an_installed_plugin_is_imported_in_its_worker_and_a_checking_process_never_in_the_run(
        seq, alone, tmp_path, monkeypatch):
    """An installed plugin whose module patches cv2.cvtColor at import: listing it (--help, --methods) used to
    import it in the run's process, where the built-ins' gray images are made; the built-ins keep their bytes."""
    import cv2

    from emulator.autoexposure import registry

    site = tmp_path / "site"
    (site / "patch_ae").mkdir(parents=True)
    (site / "patch_ae" / "__init__.py").write_text(PATCHER)
    info = site / "patch_ae-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: patch-ae\nVersion: 0.1\n")
    (site / "exiting_ae.py").write_text("import os\nos._exit(5)\n")
    (info / "entry_points.txt").write_text("[exposim.methods]\nexits-ae = exiting_ae:X\npatch-ae = patch_ae:PatchAE\n"
                                           "broken-ae = patch_ae:Nothing\n")
    monkeypatch.syspath_prepend(str(site))
    registry._installed.cache_clear()
    monkeypatch.setattr(registry, "_installed", registry._installed)
    real = cv2.cvtColor
    try:
        plugins = registry.installed_methods()
        assert plugins["patch-ae"].error is None and plugins["patch-ae"].factory is None
        assert plugins["broken-ae"].error.startswith("cannot load patch_ae:Nothing: AttributeError")
        assert plugins["exits-ae"].error == ("cannot load exiting_ae:X: its import ended the checking process "
                                             "(exit status 5)")
        out = tmp_path / "run"
        assert main(["run", str(seq), "--methods", f"{BUILTINS},patch-ae", "-o", str(out), "--no-progress"]) == 0
        assert "patch_ae" not in sys.modules and cv2.cvtColor is real
        for m, data in alone.items():
            assert (out / m / "exposures.csv").read_bytes() == data, m
        assert json.loads((out / "run.json").read_text())["method_status"]["patch-ae"] == "ok"
    finally:
        registry._installed.cache_clear()


def test_a_table_rewritten_by_a_plugin_is_named_at_the_end_of_the_run(seq, plugin_dir, tmp_path, monkeypatch,
                                                                        capsys):
    """A plugin running as the user can write into the run folder (docs/faults.md); the run compares each table
    with the rows it wrote, and names the one that differs in run.json and in one warning."""
    out = tmp_path / "run"
    monkeypatch.setenv("BOUNDARY_TABLE", str(out / "classical-50" / "exposures.csv"))
    monkeypatch.syspath_prepend(str(plugin_dir))
    assert main(["run", str(seq), "--methods", "classical-50,shim,boundary_plugins:RewritesTable", "-o", str(out),
                 "--no-progress"]) == 0
    said = [ln for ln in capsys.readouterr().err.splitlines() if "differs from the rows this run wrote" in ln]
    assert len(said) == 1 and "the table of classical-50 differs" in said[0] and "shim" not in said[0]
    assert json.loads((out / "run.json").read_text())["tables_changed"] == ["classical-50"]
