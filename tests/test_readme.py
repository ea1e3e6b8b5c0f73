"""README.md stays true: its command table is the registered commands, CI runs its test command."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from emulator.cli import build_parser, load_commands

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def table_commands(text: str) -> list[str]:
    """The commands of the README's "## Commands" table, in order (``exposim NAME ...`` cells)."""
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
    assert table_commands(README) == registered


def test_table_parser_sees_a_missing_row():
    shortened = README.replace("| `exposim render SCENE", "| render SCENE")
    assert "render" not in table_commands(shortened)


def test_selector_choices_in_the_table_are_the_parsers():
    parser = build_parser()
    sub = parser._subparsers._group_actions[0].choices  # noqa: SLF001 - argparse has no public accessor
    for cmd in ("emulate", "run"):
        action = next(a for a in sub[cmd]._actions if "--selector" in a.option_strings)
        row = next(line for line in README.splitlines() if line.startswith(f"| `exposim {cmd} "))
        assert f"--selector {'|'.join(action.choices)}".replace("|", r"\|") in row, (cmd, action.choices)


def test_ci_runs_the_readme_test_command():
    ci = (ROOT / ".ci" / "run").read_text()
    extract = next(line for line in ci.splitlines() if line.startswith("cmd=$(awk"))
    got = subprocess.run(["bash", "-c", f'{extract}\nprintf "%s" "$cmd"'], cwd=ROOT, capture_output=True,
                         text=True, check=True).stdout
    block = README.split("<!-- test-command -->", 1)[1].split("```", 2)[1].strip()
    assert got == block
    assert got.endswith("python -m pytest -q")
