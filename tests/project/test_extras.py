"""Optional extras: the real-data core runs without them; a command that needs one says so in one line.

The extras are hidden from a child ``exposim`` process by a ``sitecustomize`` module that
puts ``None`` into ``sys.modules`` for each name (so ``import mitsuba`` raises
ModuleNotFoundError exactly as when the package is not installed).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from emulator.errors import ExposimError, MissingExtraError
from emulator.extras import EXTRAS, MODULE_EXTRA, missing_extra_message, missing_modules, require

ROOT = Path(__file__).resolve().parents[2]
SYNTH_AND_DASK = "mitsuba,drjit,OpenEXR,Imath,colour,pyoidn,dask,distributed"

SHIM = """import os, sys
for _name in os.environ.get("EXPOSIM_TEST_HIDE", "").split(","):
    if _name:
        sys.modules[_name] = None
"""


def exposim_without(tmp_path: Path, hidden: str, *args: str) -> subprocess.CompletedProcess:
    shim = tmp_path / "hide"
    shim.mkdir(exist_ok=True)
    (shim / "sitecustomize.py").write_text(SHIM)
    env = dict(os.environ, EXPOSIM_TEST_HIDE=hidden,
               PYTHONPATH=os.pathsep.join([str(shim), str(ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-c", "import sys; from emulator.commands.cli import main; sys.exit(main())", *args],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)


def test_shim_really_hides_the_module(tmp_path):
    got = exposim_without(tmp_path, "mitsuba", "--version")
    assert got.returncode == 0
    shim_env = dict(os.environ, EXPOSIM_TEST_HIDE="mitsuba", PYTHONPATH=str(tmp_path / "hide"))
    probe = subprocess.run([sys.executable, "-c", "import mitsuba"], env=shim_env, capture_output=True, text=True)
    assert probe.returncode == 1 and "ModuleNotFoundError" in probe.stderr


@pytest.mark.parametrize("argv", [["synth", "forest_winter", "-o", "out"], ["render", "forest_winter", "-o", "out"],
                                  ["demo", "-o", "out", "--quick"], ["validate", "emulation", "-o", "out", "--quick"],
                                  ["validate", "live", "-o", "out", "--quick"],
                                  ["validate", "blur", "-o", "out", "--quick"]])
def test_synthetic_commands_without_the_extra_fail_in_one_line_naming_it(tmp_path, argv):
    got = exposim_without(tmp_path, SYNTH_AND_DASK, *argv)
    assert got.returncode == 1
    lines = got.stderr.strip().splitlines()
    assert len(lines) == 1, got.stderr
    assert lines[0] == (f"exposim {argv[0]}: error: the 'synth' extra is not installed (no module mitsuba): "
                        "pip install 'exposim[synth]'")
    assert not (tmp_path / "out").exists()  # refused before any output


def _leaf_commands(parser, words=()):
    """(words, parser) of every command that runs something (sub-commands of sub-commands too)."""
    import argparse

    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield words, parser
        return
    for name, child in subs[0].choices.items():
        yield from _leaf_commands(child, (*words, name))


#: Commands of the validation package that read real recordings only (no render, no synthetic camera).
REAL_DATA_CHECKS = {"validate native"}


def test_every_command_of_the_synthetic_layer_declares_the_synth_extra():
    """A command whose code lives in synth, scenes or validation renders or reads renders: the
    dispatcher must check the 'synth' extra before it runs (one line, no output), not the walk."""
    from emulator.commands.cli import build_parser

    checked = []
    for words, parser in _leaf_commands(build_parser()):
        func = parser.get_default("func")
        module = getattr(func, "__module__", "") or ""
        if " ".join(words) in REAL_DATA_CHECKS:  # validation code on real recordings only: no extra
            assert parser.get_default("extras") == (), " ".join(words)
            continue
        if module.split(".", 1)[0] in ("synth", "scenes", "validation"):
            assert "synth" in (parser.get_default("extras") or ()), " ".join(words)
            checked.append(" ".join(words))
    assert {"validate live", "validate blur", "demo", "render", "synth"} <= set(checked)


def test_real_data_commands_run_without_the_extras(tmp_path, sample_seq):
    got = exposim_without(tmp_path, SYNTH_AND_DASK, "info", str(sample_seq), "--json")
    assert got.returncode == 0, got.stderr
    assert '"cycles"' in got.stdout
    got = exposim_without(tmp_path, SYNTH_AND_DASK, "run", str(sample_seq), "--methods", "classical-50,shim",
                          "--save", "none", "-o", "run", "-q")
    assert got.returncode == 0, got.stderr
    assert (tmp_path / "run" / "results.json").is_file()


def test_dask_scheduler_without_the_extra_names_it(tmp_path, sample_seq):
    got = exposim_without(tmp_path, "dask,distributed", "run", str(sample_seq.parent), "--sequences", "all",
                          "--methods", "classical-50", "--save", "none", "-o", "out", "--scheduler", "local", "-q")
    assert got.returncode == 1
    assert got.stderr.strip().splitlines() == [
        "exposim run: error: a Dask scheduler needs the 'dask' extra (no module dask): pip install 'exposim[dask]'"]
    # without --scheduler a dataset run falls back to serial when Dask is not installed
    got = exposim_without(tmp_path, "dask,distributed", "run", str(sample_seq.parent), "--sequences", "all",
                          "--methods", "classical-50", "--save", "none", "-o", "out2", "--json", "-q")
    assert got.returncode == 0, got.stderr
    assert '"scheduler": "serial"' in got.stdout


def test_module_not_found_of_an_extra_becomes_the_one_line():
    exc = ModuleNotFoundError("No module named 'mitsuba.python'", name="mitsuba.python")
    assert missing_extra_message(exc) == ("the 'synth' extra is not installed (no module mitsuba): "
                                          "pip install 'exposim[synth]'")
    assert missing_extra_message(ModuleNotFoundError("x", name="numpy")) is None
    assert missing_extra_message(ValueError("x")) is None


def test_require_checks_without_importing(monkeypatch):
    monkeypatch.setitem(sys.modules, "colour", None)
    assert missing_modules("synth") == ["colour"] or "colour" in missing_modules("synth")
    with pytest.raises(MissingExtraError, match=r"pip install 'exposim\[synth\]'") as err:
        require("synth", "render")
    assert isinstance(err.value, ExposimError) and isinstance(err.value, ImportError)
    with pytest.raises(ValueError, match="unknown extra 'gpu'"):
        require("gpu")


def test_extras_in_pyproject_match_the_module_map():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    optional = project["optional-dependencies"]
    core = " ".join(project["dependencies"]).lower()
    for name in ("mitsuba", "drjit", "openexr", "colour-science", "pyoidn", "dask"):
        assert name not in core, name
    assert "opencv-python-headless" in core and "contrib" not in core
    synth = " ".join(optional["synth"]).lower()
    for dist in ("mitsuba==3.9.1", "drjit==1.5.0", "openexr", "colour-science", "pyoidn"):
        assert dist in synth
    assert optional["dask"] == ["dask[distributed]>=2024.1"]
    assert optional["all"] == ["exposim[synth,dask]"]
    assert set(MODULE_EXTRA.values()) == set(EXTRAS) <= set(optional)
