"""README.md and docs/ stay true: the command table (docs/commands.md) is the registered commands, CI runs
the README's test command, and every relative link of the README and docs/ resolves inside the repository."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from emulator.commands.cli import build_parser, load_commands

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text(encoding="utf-8")
COMMANDS = (ROOT / "docs" / "commands.md").read_text(encoding="utf-8")


def table_commands(text: str) -> list[str]:
    """The commands of the "## Commands" table of docs/commands.md, in order (``exposim NAME ...`` cells)."""
    section = text.split("## Commands", 1)[1].split("\n## ", 1)[0]
    names = []
    for line in section.splitlines():
        m = re.match(r"\| `exposim ([a-z][a-z0-9-]*)", line)
        if m and m.group(1) not in names:
            names.append(m.group(1))
    return names


def test_command_table_lists_every_registered_command_in_help_order():
    registered = [c.name for c in load_commands() if c.error is None]
    assert sorted(registered) == ["bench", "cache", "calibrate", "demo", "emulate", "export", "info", "new-method",
                                  "render", "run",
                                  "synth", "validate"]
    assert table_commands(COMMANDS) == registered


def test_table_parser_sees_a_missing_row():
    shortened = COMMANDS.replace("| `exposim render SCENE", "| render SCENE")
    assert "render" not in table_commands(shortened)


def test_selector_choices_in_the_table_are_the_parsers():
    parser = build_parser()
    sub = parser._subparsers._group_actions[0].choices  # noqa: SLF001 - argparse has no public accessor
    for cmd in ("emulate", "run"):
        action = next(a for a in sub[cmd]._actions if "--selector" in a.option_strings)
        row = next(line for line in COMMANDS.splitlines() if line.startswith(f"| `exposim {cmd} "))
        assert f"--selector {'|'.join(action.choices)}".replace("|", r"\|") in row, (cmd, action.choices)


def test_ci_runs_the_readme_test_command():
    ci = (ROOT / ".ci" / "run").read_text()
    extract = next(line for line in ci.splitlines() if line.startswith("cmd=$(awk"))
    got = subprocess.run(["bash", "-c", f'{extract}\nprintf "%s" "$cmd"'], cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout
    block = README.split("<!-- test-command -->", 1)[1].split("```", 2)[1].strip()
    assert got == block
    assert got.endswith("python -m pytest -q -n 2 --dist loadfile")


def _relative_links(text: str) -> list[str]:
    return [m for m in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text) if "://" not in m]


def test_every_relative_link_of_the_readme_and_docs_resolves_inside_the_repository():
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    broken = []
    for page in pages:
        text = page.read_text(encoding="utf-8")
        for link in _relative_links(text):
            target = (page.parent / link).resolve()
            if not target.exists() or ROOT.resolve() not in target.parents:
                broken.append(f"{page.relative_to(ROOT)} -> {link}")
        if "../shared" in text or "shared/DESIGN" in text:
            broken.append(f"{page.relative_to(ROOT)} names a file outside the repository")
    assert broken == []
    assert _relative_links("[a](docs/x.md) [b](https://h/y.md) [c](y.md#s)") == ["docs/x.md", "y.md"]


def test_readme_is_short_and_links_the_reference():
    assert len(README.splitlines()) <= 90
    for page in ("docs/commands.md", "docs/datasets.md", "docs/plugins.md", "docs/design.md"):
        assert f"]({page})" in README, page


def test_every_results_page_names_its_date_commit_and_machine():
    pages = sorted((ROOT / "docs" / "results").glob("*.md"))
    assert len(pages) >= 4
    for page in pages:
        head = page.read_text(encoding="utf-8").splitlines()[:5]
        assert head[2] == "| measured | commit | machine |", page.name
        date, commit, machine = (c.strip() for c in head[4].strip("|").split("|"))
        assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", date) and re.fullmatch(r"`[0-9a-f]{7,40}`", commit), page.name
        assert "cores" in machine, page.name


def _setup_commands() -> list[str]:
    """The one-line commands of the README's set-up section, in order."""
    section = README.split("## Set-up", 1)[1].split("\n## ", 1)[0]
    return [block.strip() for block in section.split("```")[1::2]]


def test_setup_commands_install_into_a_virtual_environment_in_one_line():
    """Debian's python3 refuses pip outside a virtual environment (PEP 668), so every set-up
    command makes `.venv` and activates it before pip, in the same line."""
    commands = _setup_commands()
    assert len(commands) == 3
    assert commands[0].endswith("pip install -e '.[all]' && exposim demo")
    assert commands[1].endswith("pip install -e '.[all,test]' && python -m pytest -q -n 2 --dist loadfile")
    for cmd in commands:
        assert "\n" not in cmd, cmd
        steps = cmd.split(" && ")
        assert steps[:2] == ["apt-get update", steps[1]] and "python3-venv" in steps[1].split(), cmd
        assert steps[2:4] == ["python3 -m venv .venv", ". .venv/bin/activate"], cmd
        assert all("pip" not in s.split() for s in steps[:4]), cmd
    for cmd in commands[:2]:  # Dr.Jit's library loads libatomic.so.1, absent from a minimal Debian 12
        assert {"libllvm19", "libatomic1"} <= set(cmd.split(" && ")[1].split()), cmd
    assert "/.venv/" in (ROOT / ".gitignore").read_text().splitlines()


def test_activating_the_virtual_environment_works_under_the_ci_shell_options(tmp_path):
    """`. .venv/bin/activate` survives `bash -euo pipefail` (how .ci/run runs the test command)."""
    import sys

    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(tmp_path / ".venv")], check=True)
    got = subprocess.run(["bash", "-euo", "pipefail", "-c", ". .venv/bin/activate && python -c 'import sys; print(sys.prefix)'"],
                         cwd=tmp_path, capture_output=True, text=True)
    assert got.returncode == 0, got.stderr
    assert Path(got.stdout.strip()).resolve() == (tmp_path / ".venv").resolve()


def test_the_test_run_collects_nothing_under_the_virtual_environment(tmp_path):
    """The project's pytest options (testpaths, --doctest-modules) with a `.venv` beside the packages:
    neither `pytest` nor `pytest .` imports a module of the virtual environment."""
    import sys

    options = (ROOT / "pyproject.toml").read_text(encoding="utf-8").split("[tool.pytest.ini_options]", 1)[1]
    options = options.split("\n[", 1)[0]
    (tmp_path / "pyproject.toml").write_text("[tool.pytest.ini_options]" + options, encoding="utf-8")
    testpaths = re.search(r"testpaths = \[(.*)\]", options).group(1).replace('"', "").split(", ")
    assert "." not in testpaths and ".venv" not in testpaths
    for pkg in testpaths:
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / f"m_{pkg}.py").write_text('def f():\n    """\n    >>> 1 + 1\n    2\n    """\n')
    venv_lib = tmp_path / ".venv" / "lib" / "python3.11" / "site-packages"
    venv_lib.mkdir(parents=True)
    (tmp_path / ".venv" / "pyvenv.cfg").write_text("home = /usr/bin\n")
    (venv_lib / "test_theirs.py").write_text("raise SystemExit('collected from .venv')\n")
    (venv_lib / "theirs.py").write_text("raise SystemExit('collected from .venv')\n")
    for args in ([], ["."]):
        got = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider", *args],
                             cwd=tmp_path, capture_output=True, text=True)
        assert got.returncode == 0, got.stdout + got.stderr
        assert ".venv" not in got.stdout and len(re.findall(r"::m_\w+\.f$", got.stdout, re.M)) == len(testpaths)
