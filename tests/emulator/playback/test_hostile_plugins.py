"""Hostile AE plugins, written independently of tests/test_faults_*.py (issue 24).

Each hostile method runs FIRST beside classical-50 and shim on a small synthetic recording;
the outcome asserted is that classical-50's and shim's files are byte-identical to a run
without the hostile method, that the run finished (results.json, report.md, run.json complete)
and that the hostile method's failure, where it fails, is named in its status.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from emulator.commands.cli import main
from test_playback import write_static_sequence

HERE = Path(__file__).resolve().parent
OTHERS = ("classical-50", "shim")
N_CYCLES = 5
MOD = "hostile_plugins"


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
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
def baseline(seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("hbase") / "run"
    sys.path.insert(0, str(HERE))
    try:
        assert main(["run", str(seq), "--methods", ",".join(OTHERS), "-o", str(out), "--save", "png16", "-q"]) == 0
    finally:
        sys.path.remove(str(HERE))
    return {name: _files(out, name) for name in OTHERS}


def _run(seq, out, cls, *extra):
    return main(["run", str(seq), "--methods", f"{MOD}:{cls}," + ",".join(OTHERS), "-o", str(out),
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


def _run_many(seq, out, classes, *extra):
    methods = ",".join(f"{MOD}:{c}" for c in classes) + "," + ",".join(OTHERS)
    return main(["run", str(seq), "--methods", methods, "-o", str(out), "--save", "png16", "-q", *extra])


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_no_method_can_write_into_the_shared_image(seq, baseline, tmp_path, jobs):
    """Every write route at once (each hostile method runs before classical-50 and shim)."""
    import hostile_plugins

    out = tmp_path / "run"
    assert _run_many(seq, out, WRITERS + POINTER_WRITERS, "--jobs", jobs) == 0
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
def test_process_state_does_not_leak(seq, baseline, tmp_path, cls, capsys):
    out = tmp_path / "run"
    stdout, stderr = sys.stdout, sys.stderr
    try:
        assert _run(seq, out, cls) == 0
        # a method that replaced sys.stdout for good does not keep it after its call
        assert sys.stdout is stdout and sys.stderr is stderr
    finally:
        sys.stdout, sys.stderr = stdout, stderr
    _check_others(out, baseline)


@pytest.fixture(scope="module")
def kim_baseline(seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("hkim") / "run"
    assert main(["run", str(seq), "--methods", "kim", "-o", str(out), "-q"]) == 0
    return (out / "kim" / "exposures.csv").read_bytes()


@pytest.mark.parametrize("cls", ["Seterr", "SeterrCall", "WarningsError"])
def test_numpy_error_state_and_warning_filters_do_not_reach_kim(seq, kim_baseline, tmp_path, cls):
    import warnings

    import numpy as np

    out = tmp_path / "run"
    before = np.geterr()
    with warnings.catch_warnings():
        filters = list(warnings.filters)
        assert main(["run", str(seq), "--methods", f"{MOD}:{cls},kim", "-o", str(out), "-q"]) == 0
        # the method's process-wide settings did not outlive its call
        assert warnings.filters == filters
    assert np.geterr() == before
    results = json.loads((out / "results.json").read_text())
    assert results["methods"]["kim"]["status"] == "ok", results["methods"]["kim"]["status"]
    assert (out / "kim" / "exposures.csv").read_bytes() == kim_baseline


def test_chdir_does_not_split_the_run_folder(seq, baseline, tmp_path, monkeypatch):
    import hostile_plugins

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setattr(hostile_plugins.Chdir, "target", str(elsewhere))
    assert main(["run", str(seq), "--methods", f"{MOD}:Chdir," + ",".join(OTHERS), "-o", "rel/run",
                 "--save", "png16", "-q"]) == 0
    assert os.getcwd() == str(work)
    assert list(elsewhere.iterdir()) == []
    out = work / "rel" / "run"
    _check_others(out, baseline)
    assert (out / "h-chdir" / "exposures.csv").is_file()
    assert not (out / "run.lock").exists()


EXITS = {"Exit0": "sys.exit(0)", "Exit3": "sys.exit(3)", "RaiseBase": "OsExitLike",
         "RaiseGeneratorExit": "GeneratorExit", "ExitLater": "sys.exit(0)"}


def test_exits_and_base_exceptions_fail_only_that_method(seq, baseline, tmp_path):
    import hostile_plugins

    out = tmp_path / "run"
    assert _run_many(seq, out, list(EXITS)) == 0
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


def test_strict_exit_code_with_an_exiting_method(seq, tmp_path):
    out = tmp_path / "run"
    assert _run(seq, out, "Exit0", "--strict") == 1
    assert (out / "results.json").is_file()


@pytest.mark.parametrize("cls", ["ExitInReset", "RaiseInReset", "HostileAttrs"])
def test_hostile_reset_or_attributes(seq, baseline, tmp_path, cls, capsys):
    """reset() and attributes the loop reads are the plugin's code too."""
    import hostile_plugins

    out = tmp_path / "run"
    rc = _run(seq, out, cls)
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


def test_a_factory_that_exits_is_one_line_naming_the_plugin(seq, tmp_path, capsys):
    out = tmp_path / "run"
    assert _run(seq, out, "ExitInFactory") == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "h-exit-factory" in err and "sys.exit(0)" in err, err


RETURNS = {"RetStr": "'12.5'", "RetTrue": "True", "RetNpBool": "True", "RetNan": "NaN", "RetNeg": "-1.0",
           "RetZero": "0", "RetInf": "inf", "RetNone": "None", "RetBigInt": None, "RetArray": None,
           "RetComplex": None, "RetNanArray0d": "NaN"}


def test_bad_return_values_fail_that_method_alone(seq, baseline, tmp_path):
    import hostile_plugins

    out = tmp_path / "run"
    assert _run_many(seq, out, sorted(RETURNS)) == 0
    results = _check_others(out, baseline)
    for cls, words in RETURNS.items():
        name = getattr(hostile_plugins, cls).name
        status = _status(results, name)
        assert status.startswith("failed") and "cycle 0" in status, (cls, status)
        if words:
            assert words in status, (cls, status)
        assert (out / name / "exposures.csv").read_text().count("\n") == 1


def test_a_huge_finite_return_is_clamped_and_flagged(seq, baseline, tmp_path):
    out = tmp_path / "run"
    assert _run(seq, out, "RetHuge") == 0
    results = _check_others(out, baseline)
    assert _status(results, "h-ret-huge") == "ok"
    rows = (out / "h-ret-huge" / "exposures.csv").read_text().splitlines()
    header = rows[0].split(",")
    first = dict(zip(header, rows[1].split(",")))
    assert float(first["next_ms"]) == 50.0 and first["clamped"] == "1" and float(first["proposed_ms"]) == 1e300


def test_a_slow_method_fails_on_the_timeout_and_the_others_are_kept(seq, baseline, tmp_path, monkeypatch):
    """The 0.1 s limit reaches only the slow method (its sleep of 0.4 s is past it on any machine); the
    built-ins keep the default limit, so a loaded machine cannot make them fail (issue 46)."""
    from emulator.playback import workers

    real_init = workers.MethodWorker.__init__

    def init(self, item, *, timeout_s, **kw):
        slow = isinstance(item, str) and item.endswith(":Slow")
        real_init(self, item, timeout_s=timeout_s if slow else workers.DEFAULT_METHOD_TIMEOUT_S, **kw)

    monkeypatch.setattr(workers.MethodWorker, "__init__", init)
    out = tmp_path / "run"
    assert _run(seq, out, "Slow", "--method-timeout", "0.1") == 0
    results = _check_others(out, baseline)
    status = _status(results, "h-slow")
    assert status.startswith("failed") and "0.1" in status and "cycle 0" in status, status


@pytest.mark.parametrize("cls, words", [("BadName", "../escape"), ("BuiltinName", "classical-50"),
                                        ])
def test_bad_plugin_names_are_refused_in_one_line(seq, tmp_path, cls, words, capsys):
    out = tmp_path / "sub" / "run"
    assert _run(seq, out, cls) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err, err
    assert not (tmp_path / "escape").exists() and not (tmp_path / "sub" / "escape").exists()


def test_a_method_given_the_response_cannot_change_it_for_the_others(seq, baseline, tmp_path):
    out = tmp_path / "run"
    rc = _run(seq, out, "ResponseMutator")
    assert rc == 0
    _check_others(out, baseline)


def test_prints_never_reach_json_output(seq, tmp_path):
    """A real process: --json stdout is one JSON document whatever the method prints."""
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "emulator.commands.cli", "run", str(seq), "--methods",
                           f"{MOD}:Printer,classical-50", "-o", str(out), "-q", "--json"],
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["status"] == "complete"
    assert "hostile" not in proc.stdout and "hostile" not in proc.stderr
    kept = (out / "h-printer" / "output.txt").read_text()
    assert "printed in next_exposure" in kept and "to stderr" in kept


def test_a_background_thread_printing_does_not_corrupt_json(seq, tmp_path):
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "emulator.commands.cli", "run", str(seq), "--methods",
                           f"{MOD}:ThreadPrinter,classical-50", "-o", str(out), "-q", "--json"],
                          capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["status"] == "complete", proc.stdout
