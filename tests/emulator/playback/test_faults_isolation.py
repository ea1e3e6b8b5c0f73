"""Fault suite, issue 24 (method isolation): hostile plugins cannot change what the other methods
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
from test_playback import write_static_sequence

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
