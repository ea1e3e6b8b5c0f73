"""Faults of AE plugins: a hostile method cannot change what the other methods see, nor the run's state, output or exit; it fails alone, by name (two suites written independently, one after the other).

Fault suite, issue 24 (method isolation): hostile plugins cannot change what the other methods
see, nor the run's state, output or exit; each fails alone, by name, with the reason.

Every case runs the hostile plugin between built-in methods and asserts that the built-ins'
CSV bytes equal a run without it, that the run completes with results.json and report.md, and
that the plugin's row names what it did.
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np
import pytest

from emulator.autoexposure import AutoExposureError, MethodFailed
from emulator.autoexposure.isolation import call_method, captured_output, frozen, is_frozen
from emulator.commands.cli import main
from emulator.playback import run
from tests.emulator.playback.test_playback import write_static_sequence
import subprocess
from pathlib import Path

HOSTILE = '''
import os, sys
import cv2
import numpy as np


class _Base:
    name = None

    def __init__(self):
        self.calls = 0

    def reset(self):
        self.calls = 0

    def next_exposure(self, raw, exposure_ms):
        self.calls += 1
        self.act(raw, exposure_ms)
        return 0.02


class Mutator(_Base):
    name = "mutator"

    def act(self, raw, t):
        raw.setflags(write=True)
        raw[...] = 0


class CvMutator(_Base):
    name = "cv-mutator"

    def act(self, raw, t):
        cv2.GaussianBlur(raw, (3, 3), 0, dst=raw)


class SetErr(_Base):
    name = "seterr"

    def act(self, raw, t):
        np.seterr(all="raise")


class Exit0(_Base):
    name = "exit0"

    def act(self, raw, t):
        if self.calls == 2:
            sys.exit(0)


class Exit3(_Base):
    name = "exit3"

    def act(self, raw, t):
        sys.exit(3)


class Chdir(_Base):
    name = "chdir"
    to = None

    def act(self, raw, t):
        os.chdir(os.environ["HOSTILE_CHDIR"])


class Printer(_Base):
    name = "printer"

    def act(self, raw, t):
        print("hello from the plugin")
        print("and on stderr", file=sys.stderr)


def exiting_factory(**kwargs):
    sys.exit(2)
'''

BUILTINS = "classical-50,shim,kim"


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("faults") / "seq", n_cycles=6, shape=(32, 48))
    return root


@pytest.fixture(scope="module")
def alone(seq, tmp_path_factory):
    """The built-ins' CSV bytes without any hostile plugin."""
    out = tmp_path_factory.mktemp("alone") / "run"
    assert main(["run", str(seq), "--methods", BUILTINS, "-o", str(out), "--no-progress"]) == 0
    return {m: (out / m / "exposures.csv").read_bytes() for m in BUILTINS.split(",")}


@pytest.fixture
def hostile(tmp_path, monkeypatch):
    (tmp_path / "hostile_mod.py").write_text(HOSTILE)
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop("hostile_mod", None)
    yield tmp_path
    sys.modules.pop("hostile_mod", None)


def _run_with(seq, tmp_path, plugin, *extra):
    out = tmp_path / "mixed"
    a, b, c = BUILTINS.split(",")
    rc = main(["run", str(seq), "--methods", f"{a},hostile_mod:{plugin},{b},{c}", "-o", str(out), "--no-progress",
               *extra])
    return rc, out


def _assert_others_unchanged_and_run_complete(out, alone, name, why):
    for m, data in alone.items():
        assert (out / m / "exposures.csv").read_bytes() == data, m
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "complete"
    assert info["method_status"][name] == why
    assert all(info["method_status"][m] == "ok" for m in alone)
    results = json.loads((out / "results.json").read_text())
    assert results["methods"][name]["status"] == why
    assert (out / "report.md").is_file()


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_a_plugin_that_makes_its_input_writeable_changes_nothing_for_the_others(seq, alone, hostile, tmp_path, jobs):
    rc, out = _run_with(seq, tmp_path, "Mutator", "--jobs", jobs)
    assert rc == 0
    _assert_others_unchanged_and_run_complete(
        out, alone, "mutator", "failed: raised ValueError: cannot set WRITEABLE flag to True of this array at cycle 0")


def test_a_plugin_that_writes_through_cv2_dst_changes_nothing_for_the_others(seq, alone, hostile, tmp_path):
    rc, out = _run_with(seq, tmp_path, "CvMutator")
    assert rc == 0
    info = json.loads((out / "run.json").read_text())
    assert info["method_status"]["cv-mutator"].startswith("failed: raised error: ")
    _assert_others_unchanged_and_run_complete(out, alone, "cv-mutator", info["method_status"]["cv-mutator"])


def test_numpy_error_state_does_not_leak_into_kim(seq, alone, hostile, tmp_path):
    before = np.geterr()
    rc, out = _run_with(seq, tmp_path, "SetErr")
    assert rc == 0 and np.geterr() == before
    _assert_others_unchanged_and_run_complete(out, alone, "seterr", "ok")


@pytest.mark.parametrize("plugin,name,why", [
    ("Exit0", "exit0", "failed: called sys.exit(0) at cycle 1"),
    ("Exit3", "exit3", "failed: called sys.exit(3) at cycle 0"),
])
def test_sys_exit_in_a_method_is_that_methods_failure(seq, alone, hostile, tmp_path, capsys, plugin, name, why):
    rc, out = _run_with(seq, tmp_path, plugin)
    assert rc == 0
    _assert_others_unchanged_and_run_complete(out, alone, name, why)
    assert why in capsys.readouterr().out


def test_a_factory_that_exits_is_refused_in_one_line(seq, hostile, tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["run", str(seq), "--methods", "classical-50,hostile_mod:exiting_factory", "-o", str(out),
               "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1
    assert len(err) == 1 and "hostile_mod:exiting_factory" in err[0] and "sys.exit(2)" in err[0]


def test_chdir_in_a_method_neither_splits_the_run_folder_nor_moves_the_caller(seq, alone, hostile, tmp_path,
                                                                              monkeypatch):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.setenv("HOSTILE_CHDIR", str(elsewhere))
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    rc = main(["run", str(seq), "--methods", "classical-50,hostile_mod:Chdir,shim,kim", "-o", "rel-run",
               "--no-progress", "--save", "png16"])
    assert rc == 0 and os.getcwd() == str(work)
    assert list(elsewhere.iterdir()) == []
    out = work / "rel-run"
    _assert_others_unchanged_and_run_complete(out, alone, "chdir", "ok")
    assert any((out / "classical-50").rglob("*.png"))


def test_a_method_that_prints_leaves_json_output_intact(seq, alone, hostile, tmp_path, capsys):
    rc, out = _run_with(seq, tmp_path, "Printer", "--json")
    captured = capsys.readouterr()
    assert rc == 0
    doc = json.loads(captured.out)  # one JSON document: nothing the plugin printed
    assert doc["methods"]["printer"]["status"] == "ok"
    assert "hello" not in captured.out and "stderr" not in captured.err
    assert (out / "printer" / "output.txt").read_text() == 6 * "hello from the plugin\nand on stderr\n"
    assert captured_output("printer") == ("", 0)  # handed to the run folder
    assert not (out / "shim" / "output.txt").exists()
    _assert_others_unchanged_and_run_complete(out, alone, "printer", "ok")


def test_in_memory_api_isolates_too(seq, hostile):
    a = run(seq, "classical-50,shim")
    b = run(seq, "hostile_mod:Mutator,classical-50,hostile_mod:Exit3,shim", jobs=2)
    for m in ("classical-50", "shim"):
        assert [s.next_ms for s in a.steps[m]] == [s.next_ms for s in b.steps[m]]
    assert b.failed["exit3"] == "failed: called sys.exit(3) at cycle 0"


def test_call_method_contract():
    class Raiser:
        name = "r"

        def next_exposure(self, raw, t):
            raise SystemExit("bye")

    class Interrupt:
        name = "i"

        def next_exposure(self, raw, t):
            raise KeyboardInterrupt

    raw = np.arange(64, dtype=np.uint16).reshape(8, 8)
    with pytest.raises(MethodFailed, match=r"called sys.exit\('bye'\)"):
        call_method(Raiser(), raw, 4.0)
    with pytest.raises(KeyboardInterrupt):
        call_method(Interrupt(), raw, 4.0)
    f = frozen(raw)
    assert is_frozen(f) and frozen(raw) is f and frozen(f) is f and np.array_equal(f, raw)
    with pytest.raises(ValueError):
        f.setflags(write=True)
    assert isinstance(MethodFailed("x"), AutoExposureError)


# ------------------------------------------------------------------------------------------------
# Hostile AE plugins, written independently of the suite above (issue 24).
#
# Each hostile method runs FIRST beside classical-50 and shim on a small synthetic recording;
# the outcome asserted is that classical-50's and shim's files are byte-identical to a run
# without the hostile method, that the run finished (results.json, report.md, run.json complete)
# and that the hostile method's failure, where it fails, is named in its status.
# ------------------------------------------------------------------------------------------------
HERE = Path(__file__).resolve().parent
OTHERS = ("classical-50", "shim")
N_CYCLES = 5
MOD = "hostile_plugins"


@pytest.fixture(scope="module")
def hostile_seq(tmp_path_factory):
    root, _ = write_static_sequence(tmp_path_factory.mktemp("hseq") / "seq", n_cycles=N_CYCLES, shape=(32, 48))
    return root


@pytest.fixture(autouse=True)
def _plugins_importable(monkeypatch):
    monkeypatch.syspath_prepend(str(HERE))
    yield


def _files(run_dir: Path, name: str) -> dict:
    d = run_dir / name
    return {p.relative_to(d).as_posix(): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def baseline(hostile_seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("hbase") / "run"
    sys.path.insert(0, str(HERE))
    try:
        assert main(["run", str(hostile_seq), "--methods", ",".join(OTHERS), "-o", str(out), "--save", "png16", "-q"]) == 0
    finally:
        sys.path.remove(str(HERE))
    return {name: _files(out, name) for name in OTHERS}


def _run(hostile_seq, out, cls, *extra):
    return main(["run", str(hostile_seq), "--methods", f"{MOD}:{cls}," + ",".join(OTHERS), "-o", str(out),
                 "--save", "png16", "-q", *extra])


def _check_others(out, baseline):
    results = json.loads((out / "results.json").read_text())
    assert (out / "report.md").is_file()
    assert json.loads((out / "run.json").read_text())["status"] == "complete"
    for name in OTHERS:
        assert _files(out, name) == baseline[name], name
        assert results["methods"][name]["cycles"] == N_CYCLES
        assert results["methods"][name]["status"] == "ok"
    return results


def _status(results, hostile_name):
    return results["methods"][hostile_name]["status"]


WRITERS = ["Setflags", "NdarrayBuffer", "FrombufferBase", "CtypesFromBuffer", "Cv2Dst", "Cv2DstBase",
           "UfuncOut", "InplaceBase", "TryAllWritesQuietly"]
#: Pointer-level writes pass every flag: only a private copy keeps the others' images intact.
POINTER_WRITERS = ["CtypesPointer", "ArrayInterface"]


def _run_many(hostile_seq, out, classes, *extra):
    methods = ",".join(f"{MOD}:{c}" for c in classes) + "," + ",".join(OTHERS)
    return main(["run", str(hostile_seq), "--methods", methods, "-o", str(out), "--save", "png16", "-q", *extra])


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_no_method_can_write_into_the_shared_image(hostile_seq, baseline, tmp_path, jobs):
    """Every write route at once (each hostile method runs before classical-50 and shim)."""
    import hostile_plugins

    out = tmp_path / "run"
    assert _run_many(hostile_seq, out, WRITERS + POINTER_WRITERS, "--jobs", jobs) == 0
    results = _check_others(out, baseline)
    for cls in WRITERS + POINTER_WRITERS:
        name = getattr(hostile_plugins, cls).name
        status = _status(results, name)
        if cls in ("TryAllWritesQuietly", "InplaceBase") or cls in POINTER_WRITERS:
            # every refused write swallowed (or a write into its own private copy): the method works
            assert status == "ok" and results["methods"][name]["cycles"] == N_CYCLES, (cls, status)
        else:
            assert status.startswith("failed") and "cycle 0" in status, (cls, status)


@pytest.mark.parametrize("cls", ["GlobalRng", "StdoutSwap"])
def test_process_state_does_not_leak(hostile_seq, baseline, tmp_path, cls, capsys):
    out = tmp_path / "run"
    stdout, stderr = sys.stdout, sys.stderr
    try:
        assert _run(hostile_seq, out, cls) == 0
        # a method that replaced sys.stdout for good does not keep it after its call
        assert sys.stdout is stdout and sys.stderr is stderr
    finally:
        sys.stdout, sys.stderr = stdout, stderr
    _check_others(out, baseline)


@pytest.fixture(scope="module")
def kim_baseline(hostile_seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("hkim") / "run"
    assert main(["run", str(hostile_seq), "--methods", "kim", "-o", str(out), "-q"]) == 0
    return (out / "kim" / "exposures.csv").read_bytes()


@pytest.mark.parametrize("cls", ["Seterr", "SeterrCall", "WarningsError"])
def test_numpy_error_state_and_warning_filters_do_not_reach_kim(hostile_seq, kim_baseline, tmp_path, cls):
    import warnings

    import numpy as np

    out = tmp_path / "run"
    before = np.geterr()
    with warnings.catch_warnings():
        filters = list(warnings.filters)
        assert main(["run", str(hostile_seq), "--methods", f"{MOD}:{cls},kim", "-o", str(out), "-q"]) == 0
        # the method's process-wide settings did not outlive its call
        assert warnings.filters == filters
    assert np.geterr() == before
    results = json.loads((out / "results.json").read_text())
    assert results["methods"]["kim"]["status"] == "ok", results["methods"]["kim"]["status"]
    assert (out / "kim" / "exposures.csv").read_bytes() == kim_baseline


def test_chdir_does_not_split_the_run_folder(hostile_seq, baseline, tmp_path, monkeypatch):
    import hostile_plugins

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setattr(hostile_plugins.Chdir, "target", str(elsewhere))
    assert main(["run", str(hostile_seq), "--methods", f"{MOD}:Chdir," + ",".join(OTHERS), "-o", "rel/run",
                 "--save", "png16", "-q"]) == 0
    assert os.getcwd() == str(work)
    assert list(elsewhere.iterdir()) == []
    out = work / "rel" / "run"
    _check_others(out, baseline)
    assert (out / "h-chdir" / "exposures.csv").is_file()
    assert not (out / "run.lock").exists()


EXITS = {"Exit0": "sys.exit(0)", "Exit3": "sys.exit(3)", "RaiseBase": "OsExitLike",
         "RaiseGeneratorExit": "GeneratorExit", "ExitLater": "sys.exit(0)"}


def test_exits_and_base_exceptions_fail_only_that_method(hostile_seq, baseline, tmp_path):
    import hostile_plugins

    out = tmp_path / "run"
    assert _run_many(hostile_seq, out, list(EXITS)) == 0
    results = _check_others(out, baseline)
    report = (out / "report.md").read_text()
    for cls, reason in EXITS.items():
        name = getattr(hostile_plugins, cls).name
        status = _status(results, name)
        assert status.startswith("failed") and reason in status, status
        cycle = 2 if cls == "ExitLater" else 0
        assert f"cycle {cycle}" in status, status
        rows = (out / name / "exposures.csv").read_text().splitlines()
        assert len(rows) == 1 + cycle  # header + the cycles before it failed: nothing lost, nothing invented
        assert name in report


def test_strict_exit_code_with_an_exiting_method(hostile_seq, tmp_path):
    out = tmp_path / "run"
    assert _run(hostile_seq, out, "Exit0", "--strict") == 1
    assert (out / "results.json").is_file()


@pytest.mark.parametrize("cls", ["ExitInReset", "RaiseInReset", "HostileAttrs"])
def test_hostile_reset_or_attributes(hostile_seq, baseline, tmp_path, cls, capsys):
    """reset() and attributes the loop reads are the plugin's code too."""
    import hostile_plugins

    out = tmp_path / "run"
    rc = _run(hostile_seq, out, cls)
    err = capsys.readouterr().err
    name = getattr(hostile_plugins, cls).name
    if rc == 0:
        results = _check_others(out, baseline)
        status = _status(results, name)
        # a fresh run need not call reset(); where the loop does, its failure is named
        assert status == "ok" or (status.startswith("failed") and ("sys.exit" in status or "hostile" in status)), status
    else:  # refused before the run: one line naming the plugin
        assert rc == 1 and name in err or "hostile_plugins" in err, err
        assert len(err.strip().splitlines()) == 1, err


def test_a_factory_that_exits_is_one_line_naming_the_plugin(hostile_seq, tmp_path, capsys):
    out = tmp_path / "run"
    assert _run(hostile_seq, out, "ExitInFactory") == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "h-exit-factory" in err and "sys.exit(0)" in err, err


RETURNS = {"RetStr": "'12.5'", "RetTrue": "True", "RetNpBool": "True", "RetNan": "NaN", "RetNeg": "-1.0",
           "RetZero": "0", "RetInf": "inf", "RetNone": "None", "RetBigInt": None, "RetArray": None,
           "RetComplex": None, "RetNanArray0d": "NaN"}


def test_bad_return_values_fail_that_method_alone(hostile_seq, baseline, tmp_path):
    import hostile_plugins

    out = tmp_path / "run"
    assert _run_many(hostile_seq, out, sorted(RETURNS)) == 0
    results = _check_others(out, baseline)
    for cls, words in RETURNS.items():
        name = getattr(hostile_plugins, cls).name
        status = _status(results, name)
        assert status.startswith("failed") and "cycle 0" in status, (cls, status)
        if words:
            assert words in status, (cls, status)
        assert (out / name / "exposures.csv").read_text().count("\n") == 1


def test_a_huge_finite_return_is_clamped_and_flagged(hostile_seq, baseline, tmp_path):
    out = tmp_path / "run"
    assert _run(hostile_seq, out, "RetHuge") == 0
    results = _check_others(out, baseline)
    assert _status(results, "h-ret-huge") == "ok"
    rows = (out / "h-ret-huge" / "exposures.csv").read_text().splitlines()
    header = rows[0].split(",")
    first = dict(zip(header, rows[1].split(",")))
    assert float(first["next_ms"]) == 50.0 and first["clamped"] == "1" and float(first["proposed_ms"]) == 1e300


def test_a_slow_method_fails_on_the_timeout_and_the_others_are_kept(hostile_seq, baseline, tmp_path, monkeypatch):
    """The 0.1 s limit reaches only the slow method (its sleep of 0.4 s is past it on any machine); the
    built-ins keep the default limit, so a loaded machine cannot make them fail (issue 46)."""
    from emulator.playback import workers

    real_init = workers.MethodWorker.__init__

    def init(self, item, *, timeout_s, **kw):
        slow = isinstance(item, str) and item.endswith(":Slow")
        real_init(self, item, timeout_s=timeout_s if slow else workers.DEFAULT_METHOD_TIMEOUT_S, **kw)

    monkeypatch.setattr(workers.MethodWorker, "__init__", init)
    out = tmp_path / "run"
    assert _run(hostile_seq, out, "Slow", "--method-timeout", "0.1") == 0
    results = _check_others(out, baseline)
    status = _status(results, "h-slow")
    assert status.startswith("failed") and "0.1" in status and "cycle 0" in status, status


@pytest.mark.parametrize("cls, words", [("BadName", "../escape"), ("BuiltinName", "classical-50"),
                                        ])
def test_bad_plugin_names_are_refused_in_one_line(hostile_seq, tmp_path, cls, words, capsys):
    out = tmp_path / "sub" / "run"
    assert _run(hostile_seq, out, cls) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err, err
    assert not (tmp_path / "escape").exists() and not (tmp_path / "sub" / "escape").exists()


def test_a_method_given_the_response_cannot_change_it_for_the_others(hostile_seq, baseline, tmp_path):
    out = tmp_path / "run"
    rc = _run(hostile_seq, out, "ResponseMutator")
    assert rc == 0
    _check_others(out, baseline)


def test_prints_never_reach_json_output(hostile_seq, tmp_path):
    """A real process: --json stdout is one JSON document whatever the method prints."""
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "emulator.commands.cli", "run", str(hostile_seq), "--methods",
                           f"{MOD}:Printer,classical-50", "-o", str(out), "-q", "--json"],
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["status"] == "complete"
    assert "hostile" not in proc.stdout and "hostile" not in proc.stderr
    kept = (out / "h-printer" / "output.txt").read_text()
    assert "printed in next_exposure" in kept and "to stderr" in kept


def test_a_background_thread_printing_does_not_corrupt_json(hostile_seq, tmp_path):
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "emulator.commands.cli", "run", str(hostile_seq), "--methods",
                           f"{MOD}:ThreadPrinter,classical-50", "-o", str(out), "-q", "--json"],
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["status"] == "complete", proc.stdout
