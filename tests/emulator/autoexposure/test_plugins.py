"""AE method plugins: import paths, entry points, name checks, failures kept to their own row.

The recording is the static linear-camera sequence of ``test_playback`` (``raw = round(k t
base)``), so the exposure a mean-brightness plugin settles on is known in closed form.
"""

from __future__ import annotations

import json
import math
import re
import sys
from importlib.metadata import EntryPoint
from pathlib import Path

import numpy as np
import pytest

from emulator.autoexposure import AutoExposureError, MethodFailed, PluginMethod, installed_methods, method_names, registry
from emulator.commands.cli import main
from emulator.autoexposure.methodset import build_methods, parse_methods
from emulator.errors import PlaybackError
from emulator.playback import run
from emulator.orchestration.runner import run_to_folder
from tests.emulator.playback.test_playback import K_DN_PER_MS, write_static_sequence

ROOT = Path(__file__).resolve().parents[3]
PLUGINS_DOC = (ROOT / "docs" / "plugins.md").read_text(encoding="utf-8")  # the plugin guide
GROUP = "exposim.methods"

#: Plugins that fail in each way the loop must catch, on their ``at``-th call (1-based).
PLUG = '''
import math, time


class _Base:
    at = 3

    def __init__(self, at=None):
        self.calls = 0
        self.at = self.at if at is None else at

    def reset(self):
        self.calls = 0

    def next_exposure(self, raw, exposure_ms):
        self.calls += 1
        return self.bad(exposure_ms) if self.calls == self.at else exposure_ms

class Raises(_Base):
    name = "raises"
    at = 2
    def bad(self, t):
        raise ValueError("no luck")

class NaN(_Base):
    name = "nan-ae"
    at = 3
    def bad(self, t):
        return math.nan

class Negative(_Base):
    name = "negative"
    at = 4
    def bad(self, t):
        return -1.5

class Inf(_Base):
    name = "inf-ae"
    at = 5
    def bad(self, t):
        return math.inf

class Slow(_Base):
    name = "slow"
    at = 2
    def bad(self, t):
        time.sleep(1.5)
        return t

class Kim:  # no name attribute: named after the class ('Kim'), and no next_exposure
    pass

class Shadow(_Base):
    name = "kim"

def make_scaled(factor=1.0, mode="paper"):
    """A factory (not a class): holds the exposure times ``factor``; records its mode."""
    class Scaled:
        name = "scaled"
        def reset(self):
            pass
        def next_exposure(self, raw, exposure_ms):
            return exposure_ms * factor
    s = Scaled()
    s.mode = mode
    return s
'''


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root, bases = write_static_sequence(tmp_path_factory.mktemp("plugins") / "seq", n_cycles=8, shape=(32, 48))
    return root, bases


@pytest.fixture
def plug(tmp_path, monkeypatch):
    """The module ``plug_mod`` (PLUG) and ``readme_ae`` (the plugin guide's example block), importable."""
    (tmp_path / "plug_mod.py").write_text(PLUG)
    block = PLUGINS_DOC.split("<!-- plugin-example -->", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    (tmp_path / "readme_ae.py").write_text(block)
    monkeypatch.syspath_prepend(str(tmp_path))
    for mod in ("plug_mod", "readme_ae"):
        sys.modules.pop(mod, None)
    yield tmp_path
    for mod in ("plug_mod", "readme_ae"):
        sys.modules.pop(mod, None)


def settled_ms(bases, target=0.4):
    """Exposure at which the mean raw DN of the left image is ``target`` of 4095 (linear camera)."""
    return target * 4095.0 / (K_DN_PER_MS * float(bases["left"].mean()))


def csv_cycles(path):
    lines = path.read_text().splitlines()[1:]
    return [int(line.split(",")[0]) for line in lines]


# ------------------------------------------------------------------ docs/plugins.md example, import path
def test_readme_example_is_the_shipped_example():
    block = PLUGINS_DOC.split("<!-- plugin-example -->", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    assert block == (ROOT / "examples" / "my_ae.py").read_text()
    assert 10 <= len([line for line in block.splitlines() if line.strip()]) <= 16


def test_readme_example_runs_in_closed_loop_by_import_path(seq, plug, tmp_path):
    root, bases = seq
    out = tmp_path / "run"
    summary = run_to_folder(root, "classical-50,readme_ae:MyAE", out, make_report=False)
    assert list(summary["methods"]) == ["classical-50", "my-ae"]
    info = json.loads((out / "run.json").read_text())
    assert info["method_specs"] == ["classical-50", "readme_ae:MyAE"]
    assert info["method_options"]["my-ae"]["plugin"] == "readme_ae:MyAE"
    assert info["method_status"] == {"classical-50": "ok", "my-ae": "ok"}
    res = run(root, "readme_ae:MyAE")
    steps = res.steps["my-ae"]
    assert len(steps) == 8 and steps[0].target_ms == 4.0
    # One proportional step lands on the closed-form exposure; the two roundings (capture,
    # emulation) move the mean by at most 1 DN of 1638: 1e-3 relative.
    for st in steps[1:]:
        assert st.target_ms == pytest.approx(settled_ms(bases), rel=1e-3)
    assert summary["methods"]["my-ae"]["cycles"] == 8


def test_option_reaches_the_plugin_through_the_cli(seq, plug, tmp_path, capsys):
    root, bases = seq
    out = tmp_path / "run"
    rc = main(["run", str(root), "--methods", "readme_ae:MyAE", "--option", "my-ae.target=0.2", "-o", str(out),
               "--no-progress", "--json"])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["methods"]["my-ae"]["final_exposure_ms"] == pytest.approx(settled_ms(bases, 0.2), rel=1e-3)
    assert summary["methods"]["my-ae"]["status"] == "ok"
    info = json.loads((out / "run.json").read_text())
    assert info["options"] == {"my-ae": {"target": 0.2}}
    # An option the plugin does not take is a one-line error naming the method and the option.
    rc = main(["run", str(root), "--methods", "readme_ae:MyAE", "--option", "my-ae.nope=1", "-o",
               str(tmp_path / "bad"), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 1 and "'my-ae'" in err and "'nope'" in err and "target, gain" in err


def test_resume_of_a_run_with_an_import_path_plugin(seq, plug, tmp_path, capsys):
    root, _ = seq
    out = tmp_path / "run"
    assert main(["run", str(root), "--methods", "fixed,readme_ae:MyAE", "-o", str(out), "--no-progress"]) == 0
    full = (out / "my-ae" / "exposures.csv").read_bytes()
    # Cut the plugin's CSV after 3 rows and resume: the recorded import path rebuilds it.
    lines = full.decode().splitlines(keepends=True)
    (out / "my-ae" / "exposures.csv").write_text("".join(lines[:4]))
    info = json.loads((out / "run.json").read_text())
    info["status"] = "interrupted"
    (out / "run.json").write_text(json.dumps(info))
    assert main(["run", str(root), "-o", str(out), "--resume", "--no-progress"]) == 0
    assert (out / "my-ae" / "exposures.csv").read_bytes() == full


def test_import_path_errors_are_named(seq, plug):
    with pytest.raises(AutoExposureError, match=r"'no_such_mod_q:X': no module no_such_mod_q on the Python path; run "
                                                r"from the folder that holds no_such_mod_q.py with PYTHONPATH=\."):
        build_methods("classical-50,no_such_mod_q:X")
    (plug / "imports_missing.py").write_text("import no_such_dependency_q\n")
    with pytest.raises(AutoExposureError, match=r"cannot import imports_missing: ModuleNotFoundError: No module named "
                                                r"'no_such_dependency_q'"):  # the plugin's own import fails: as it is
        build_methods("imports_missing:X")
    with pytest.raises(AutoExposureError, match=r"plug_mod has no attribute 'Missing'"):
        build_methods(["plug_mod:Missing"])
    with pytest.raises(AutoExposureError, match=r"built Kim, which has no next_exposure"):
        build_methods(["plug_mod:Kim"])


def test_a_factory_gets_mode_and_its_options(seq, plug):
    # A factory without a ``name`` attribute is named after itself (not its product's name).
    built = build_methods("plug_mod:make_scaled", mode="borealhdr", options={"make_scaled": {"factor": 2.0}})
    (name, method), = built.items()
    assert name == "make_scaled" and method.method.name == "scaled" and isinstance(method, PluginMethod) and method.mode == "borealhdr"
    raw = np.full((8, 8), 100, dtype=np.uint16)
    assert method.next_exposure(raw, 3.0) == 6.0


# ------------------------------------------------------------------ entry points
def test_entry_point_plugin_by_name(seq, plug, tmp_path):
    root, bases = seq
    plugins = installed_methods([EntryPoint("ep-ae", "readme_ae:MyAE", GROUP),
                                 EntryPoint("ep-scaled", "plug_mod:make_scaled", GROUP)])
    assert {n: p.error for n, p in plugins.items()} == {"ep-ae": None, "ep-scaled": None}
    assert parse_methods("all,ep-ae", plugins=plugins)[-2:] == ["kim", "ep-ae"]
    built = build_methods("classical-50,ep-ae", plugins=plugins, options={"ep-ae": {"target": 0.3}})
    assert list(built) == ["classical-50", "ep-ae"] and built["ep-ae"].name == "ep-ae"
    assert built["ep-ae"].source == "readme_ae:MyAE" and built["ep-ae"].target == 0.3
    res = run(root, list(built.values()))
    assert res.failed == {}
    assert res.steps["ep-ae"][-1].next_ms == pytest.approx(settled_ms(bases, 0.3), rel=1e-3)
    assert method_names([EntryPoint("ep-ae", "readme_ae:MyAE", GROUP)])[-2:] == ("kim", "ep-ae")


def test_broken_entry_point_is_named_and_harms_nothing_else(seq, plug, tmp_path, monkeypatch, capsys):
    root, _ = seq
    eps = [EntryPoint("broken-ae", "no_such_mod_q:X", GROUP), EntryPoint("ep-ae", "readme_ae:MyAE", GROUP)]
    plugins = installed_methods(eps)
    assert plugins["ep-ae"].error is None
    assert re.fullmatch(r"cannot load no_such_mod_q:X: ModuleNotFoundError: .*no_such_mod_q.*", plugins["broken-ae"].error)
    with pytest.raises(PlaybackError, match=r"broken AE method plugin\(s\): 'broken-ae' \(cannot load no_such_mod_q:X"):
        parse_methods("classical-50,broken-ae", plugins=plugins)
    # Through the command line, with these as the installed plugins:
    monkeypatch.setattr(registry, "_installed", lambda: plugins)
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    help_text = "".join(capsys.readouterr().out.split())  # argparse wraps lines, also at hyphens
    assert "installedplugins:ep-ae;" in help_text and "BROKENplugins:broken-ae(cannotloadno_such_mod_q:X" in help_text
    assert main(["run", str(root), "--methods", "classical-50,ep-ae", "-o", str(tmp_path / "ok"), "--no-progress"]) == 0
    assert "warning: AE method plugin 'broken-ae' is broken" in capsys.readouterr().err
    assert main(["run", str(root), "--methods", "broken-ae", "-o", str(tmp_path / "no"), "--no-progress"]) == 1
    warning, error = capsys.readouterr().err.strip().splitlines()
    assert warning.startswith("exposim run: warning: AE method plugin 'broken-ae' is broken (cannot load")
    assert error.startswith("exposim run: error: broken AE method plugin(s): 'broken-ae'") and "ModuleNotFoundError" in error


def test_name_collision_with_a_builtin_names_both(plug):
    plugins = installed_methods([EntryPoint("shim", "readme_ae:MyAE", GROUP)])
    assert plugins["shim"].error == ("AE method plugin readme_ae:MyAE (entry point 'shim') is named 'shim', the name of "
                                     "the built-in method 'shim' (emulator.autoexposure.shim.Shim2014); rename the plugin")
    # The built-in keeps its name.
    assert type(build_methods("shim", plugins=plugins)["shim"]).__name__ == "Shim2014"
    with pytest.raises(AutoExposureError, match=r"plug_mod:Shadow is named 'kim', the name of the built-in method "
                                                r"'kim' \(emulator.autoexposure.kim.Kim2018\)"):
        build_methods(["plug_mod:Shadow"])
    bad = installed_methods([EntryPoint("my.ae", "readme_ae:MyAE", GROUP)])
    assert "bad method name 'my.ae'" in bad["my.ae"].error


# ------------------------------------------------------------------ failures
FAILING = ["plug_mod:Raises", "plug_mod:NaN", "plug_mod:Negative", "plug_mod:Inf", "plug_mod:Slow"]
EXPECTED = {
    "raises": "failed: raised ValueError: no luck at cycle 1",
    "nan-ae": "failed: returned NaN at cycle 2",
    "negative": "failed: returned a non-positive exposure (-1.5 ms) at cycle 3",
    "inf-ae": "failed: returned a non-finite exposure (inf ms) at cycle 4",
}


def test_each_failure_gets_its_own_row_and_the_others_are_unchanged(seq, plug, tmp_path, capsys):
    root, _ = seq
    alone, mixed = tmp_path / "alone", tmp_path / "mixed"
    assert main(["run", str(root), "--methods", "classical-50,zhang", "-o", str(alone), "--no-progress"]) == 0
    rc = main(["run", str(root), "--methods", ",".join(["classical-50", *FAILING, "zhang"]), "-o", str(mixed),
               "--method-timeout", "0.5", "--no-progress"])
    out = capsys.readouterr().out
    assert rc == 0
    for name in ("classical-50", "zhang"):
        assert (mixed / name / "exposures.csv").read_bytes() == (alone / name / "exposures.csv").read_bytes()
    info = json.loads((mixed / "run.json").read_text())
    status = info["method_status"]
    assert status["classical-50"] == status["zhang"] == "ok" and info["status"] == "complete"
    for name, want in EXPECTED.items():
        assert status[name] == want
    assert status["slow"] == ("failed: did not return within the limit of 0.5 s (--method-timeout-s); its process was "
                              "stopped at cycle 1")
    results = json.loads((mixed / "results.json").read_text())
    for name, why in status.items():
        assert results["methods"][name]["status"] == why
        n = int(why.rsplit(" ", 1)[1]) if why != "ok" else 8
        assert csv_cycles(mixed / name / "exposures.csv") == list(range(n))
        assert results["methods"][name]["cycles"] == n
    report = (mixed / "report.md").read_text()
    assert "Failed methods: 5" in report and f"- raises: {EXPECTED['raises']}" in report
    assert "FAILED      5 of 7 method(s)" in out and EXPECTED["negative"] in out


def test_strict_turns_a_failure_into_exit_code_1(seq, plug, tmp_path, capsys):
    root, _ = seq
    args = ["run", str(root), "--no-progress", "--strict"]
    assert main([*args, "--methods", "fixed,plug_mod:NaN", "-o", str(tmp_path / "a")]) == 1
    assert "(--strict: exit code 1)" in capsys.readouterr().out
    assert main([*args, "--methods", "fixed,readme_ae:MyAE", "-o", str(tmp_path / "b")]) == 0


def test_in_memory_run_and_jobs_agree_on_failures(seq, plug):
    root, _ = seq
    a = run(root, ",".join(["shim", *FAILING[:4]]))
    b = run(root, ",".join(["shim", *FAILING[:4]]), jobs=2)
    assert a.failed == b.failed == EXPECTED
    assert [s.next_ms for s in a.steps["shim"]] == [s.next_ms for s in b.steps["shim"]]
    assert [s.cycle for s in a.steps["negative"]] == [0, 1, 2]


def test_plugin_wrapper_checks_every_result():
    class Bad:
        name = "bad"

        def __init__(self, value):
            self.value = value

        def next_exposure(self, raw, exposure_ms):
            return self.value

    raw = np.zeros((8, 8), np.uint16)
    for value, why in ((math.nan, "returned NaN"), (-math.inf, r"returned a non-finite exposure \(-inf ms\)"),
                       (0.0, r"non-positive exposure \(0.0 ms\)"), ("3", "returned '3', not an exposure"),
                       (np.float32(3.0), None), (True, "returned True"),
                       (None, "returned None")):
        method = PluginMethod(Bad(value), "bad", "x:Bad")
        if why is None:
            assert method.next_exposure(raw, 1.0) == 3.0
        else:
            with pytest.raises(MethodFailed, match=why):
                method.next_exposure(raw, 1.0)


def test_bad_method_timeout(seq):
    root, _ = seq
    for bad in (0, -1, math.nan, "x"):
        with pytest.raises(PlaybackError, match="method_timeout"):
            run(root, "fixed", method_timeout=bad)


# ------------------------------------------------------------------ exposim new-method
def test_new_method_writes_the_shipped_example_and_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "mine"
    assert main(["new-method", "my-ae", "--class-name", "MyAE", "-o", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["my_ae.py", "test_my_ae.py"]
    for name in ("my_ae.py", "test_my_ae.py"):
        assert (out / name).read_bytes() == (ROOT / "examples" / name).read_bytes()
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    (out / "my_ae.py").write_text("# edited\n")
    capsys.readouterr()
    assert main(["new-method", "my-ae", "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "my_ae.py" in err and "never overwrites" in err
    assert (out / "my_ae.py").read_text() == "# edited\n"
    assert (out / "test_my_ae.py").read_bytes() == before["test_my_ae.py"]
    assert main(["new-method", "zhang", "-o", str(tmp_path / "z")]) == 1
    assert "built-in method 'zhang'" in capsys.readouterr().err and not (tmp_path / "z").exists()


@pytest.mark.slow
def test_new_method_skeleton_passes_its_own_tests_and_runs(seq, tmp_path, monkeypatch):
    root, bases = seq
    out = tmp_path / "gen"
    assert main(["new-method", "fast_ae", "-o", str(out)]) == 0
    import subprocess

    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_fast_ae.py"],
                          cwd=out, capture_output=True, text=True)
    assert done.returncode == 0 and "4 passed" in done.stdout, done.stdout + done.stderr
    monkeypatch.syspath_prepend(str(out))
    sys.modules.pop("fast_ae", None)
    res = run(root, "fast_ae:FastAe")
    assert res.failed == {} and res.steps["fast_ae"][-1].next_ms == pytest.approx(settled_ms(bases), rel=1e-3)
    sys.modules.pop("fast_ae", None)


@pytest.mark.slow
def test_an_installed_distribution_registers_a_method_by_name(seq, tmp_path):
    """A distribution on the path (its dist-info, as pip would write it) makes ``pkg-ae`` a name."""
    import subprocess

    root, bases = seq
    site = tmp_path / "site"
    (site / "pkg_ae").mkdir(parents=True)
    (site / "pkg_ae" / "__init__.py").write_text((ROOT / "examples" / "my_ae.py").read_text())
    info = site / "pkg_ae-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: pkg-ae\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[exposim.methods]\npkg-ae = pkg_ae:MyAE\nbad-ae = pkg_ae:Nothing\n")
    exe = Path(sys.executable).with_name("exposim")
    env = {**__import__("os").environ, "PYTHONPATH": str(site)}
    out = tmp_path / "run"
    done = subprocess.run([str(exe), "run", str(root), "--methods", "classical-50,pkg-ae", "--option",
                           "pkg-ae.target=0.25", "-o", str(out), "--no-progress", "--json"],
                          capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    assert "exposim run: warning: AE method plugin 'bad-ae' is broken (cannot load pkg_ae:Nothing" in done.stderr
    summary = json.loads(done.stdout)
    assert list(summary["methods"]) == ["classical-50", "pkg-ae"]
    assert summary["methods"]["pkg-ae"]["final_exposure_ms"] == pytest.approx(settled_ms(bases, 0.25), rel=1e-3)
    helped = subprocess.run([str(exe), "run", "--help"], capture_output=True, text=True, env=env)
    text = "".join(helped.stdout.split())
    assert helped.returncode == 0 and "installedplugins:pkg-ae;" in text
    assert "BROKENplugins:bad-ae(cannotloadpkg_ae:Nothing:AttributeError" in text
