"""The thin ``exposim`` dispatcher: commands come from entry points, broken ones are named."""

from __future__ import annotations

import argparse
import subprocess
import sys
import types
from importlib.metadata import EntryPoint

import pytest

from emulator.commands import cli
from emulator.commands.body import CommandBody

GROUP = cli.ENTRY_POINT_GROUP


@pytest.fixture
def fake_pkg(monkeypatch):
    """An importable module with register callables: 'hello' (order 5), 'late' and a no-op."""
    mod = types.ModuleType("fake_exposim_cmds")

    def hello(sub):
        p = sub.add_parser("hello", help="say hello")
        p.add_argument("--name", default="world")
        p.set_defaults(func=lambda a: print(f"hello {a.name}") or 0)

    hello.order = 5

    def late(sub):
        sub.add_parser("late", help="comes last").set_defaults(func=lambda a: 3)

    def nothing(sub):  # forgets to add its command
        pass

    mod.hello, mod.late, mod.nothing = hello, late, nothing
    monkeypatch.setitem(sys.modules, "fake_exposim_cmds", mod)
    return mod


def _use(monkeypatch, eps):
    real = cli.load_commands
    monkeypatch.setattr(cli, "load_commands", lambda entry_points=None: real(eps))


def test_commands_sorted_by_order_then_name_and_run(fake_pkg, monkeypatch, capsys):
    eps = [EntryPoint("late", "fake_exposim_cmds:late", GROUP), EntryPoint("hello", "fake_exposim_cmds:hello", GROUP)]
    assert [c.name for c in cli.load_commands(eps)] == ["hello", "late"]
    _use(monkeypatch, eps)
    assert cli.main(["hello", "--name", "cam"]) == 0
    assert capsys.readouterr().out == "hello cam\n"
    assert cli.main(["late"]) == 3  # the command's return value is the exit code


def test_broken_command_says_why_whatever_its_arguments(fake_pkg, monkeypatch, capsys):
    eps = [EntryPoint("hello", "fake_exposim_cmds:hello", GROUP),
           EntryPoint("gone", "no_such_module_xq:register", GROUP),
           EntryPoint("mute", "fake_exposim_cmds:nothing", GROUP)]
    _use(monkeypatch, eps)

    with pytest.raises(SystemExit):
        cli.main(["--help"])
    out = " ".join(capsys.readouterr().out.split())  # argparse wraps the help column
    assert "(broken: cannot load no_such_module_xq:register: ModuleNotFoundError" in out
    assert "(broken: fake_exposim_cmds:nothing did not add a 'mute' command)" in out

    # arguments the broken command cannot know are no reason to hide the cause
    assert cli.main(["gone", "SEQ", "--cycles", "3"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "exposim: warning: command 'mute' is broken (fake_exposim_cmds:nothing did not add a 'mute' command)"
    assert err[1].startswith("exposim gone: error: this command is broken (cannot load no_such_module_xq:register")
    assert len(err) == 2

    # a working command still runs, with one warning line per broken one
    assert cli.main(["hello"]) == 0
    cap = capsys.readouterr()
    assert cap.out == "hello world\n"
    warnings = cap.err.splitlines()
    assert sorted(w.split("'")[1] for w in warnings) == ["gone", "mute"]
    assert all(w.startswith("exposim: warning: command '") for w in warnings)


def test_a_name_registered_twice_is_broken(fake_pkg):
    eps = [EntryPoint("hello", "fake_exposim_cmds:hello", GROUP), EntryPoint("hello", "fake_exposim_cmds:late", GROUP)]
    (cmd,) = cli.load_commands(eps)
    assert cmd.error == ("registered twice, by fake_exposim_cmds:hello and fake_exposim_cmds:late; "
                         "uninstall one of the packages that provide it")
    # the same entry point seen twice (an editable and a regular install) is no conflict
    (cmd,) = cli.load_commands(eps[:1] * 2)
    assert cmd.error is None


def test_installed_commands_all_load():
    """Every command pyproject.toml declares loads and registers (a packaging regression guard)."""
    parser = cli.build_parser()
    broken = {c.name: c.error for c in parser.commands if c.error is not None}
    assert broken == {}
    names = {c.name for c in parser.commands}
    assert {"info", "emulate", "run", "demo", "synth", "validate", "calibrate"} <= names


def _bodies(parser) -> dict[str, object]:
    """``{"info": func, "bench features": func, ...}``: the func default of every (sub-)sub-command."""
    found = {}

    def walk(p, prefix):
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    func = sub.get_default("func")
                    if func is not None:
                        found[f"{prefix}{name}"] = func
                    walk(sub, f"{prefix}{name} ")

    walk(parser, "")
    return found


def test_emulator_commands_name_their_bodies_and_help_imports_none():
    """Each emulator command's func is a CommandBody that loads a callable; building the parser imports no body."""
    code = ("import sys\nfrom emulator.commands.cli import build_parser\nbuild_parser()\n"
            "print(sorted(m for m in sys.modules if m.startswith('emulator.commands.') and m.endswith('_body')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    bodies = {k: v for k, v in _bodies(cli.build_parser()).items() if isinstance(v, CommandBody)}
    assert {"info", "cache", "emulate", "run", "new-method", "export", "calibrate", "bench features", "bench vo",
            "bench rpe", "bench compare"} <= set(bodies)
    assert all(b.path.startswith("emulator.commands.") and callable(b.load()) for b in bodies.values())


def test_a_command_body_is_named_module_colon_function():
    assert CommandBody("emulator.commands.info_body:info").load().__name__ == "info"
    with pytest.raises(ValueError, match="module:function"):
        CommandBody("emulator.commands.info_body.info")
