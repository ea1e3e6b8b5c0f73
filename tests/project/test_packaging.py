"""Packaging metadata: one version, py.typed, licence, citation, and no global matplotlib state."""

from __future__ import annotations

import ast
import tomllib
from importlib import metadata
from pathlib import Path

import yaml

import emulator

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("emulator", "synth", "scenes", "validation")
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def test_version_comes_from_package_metadata():
    assert emulator.__version__ == metadata.version("exposim") == PROJECT["version"]
    source = (ROOT / "emulator" / "__init__.py").read_text()
    assert PROJECT["version"] not in source  # written once, in pyproject.toml


def test_every_package_is_typed_and_ships_the_marker():
    for pkg in PACKAGES:
        assert (ROOT / pkg / "py.typed").is_file(), pkg
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert pyproject["tool"]["setuptools"]["package-data"]["*"] == ["py.typed"]


def test_licence_and_citation():
    assert PROJECT["license"] == {"text": "MIT"}
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0" and cff["license"] == "MIT"
    assert cff["version"] == PROJECT["version"]
    paper = cff["preferred-citation"]
    assert paper["title"].startswith("Exposing the Unseen: Exposure Time Emulation")
    assert [a["family-names"] for a in paper["authors"]] == ["Gamache", "Fortin", "Boxan", "Vaidis", "Pomerleau",
                                                            "Giguère"]


def _pyplot_or_backend_calls(text: str, name: str) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Import | ast.ImportFrom):
            names = [a.name for a in node.names]
            mod = node.module if isinstance(node, ast.ImportFrom) else ""
            if "matplotlib.pyplot" in names or mod == "matplotlib.pyplot" or (mod == "matplotlib" and "pyplot" in names):
                found.append((node.lineno, f"{name}:{node.lineno}: imports pyplot"))
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "use"
              and isinstance(node.func.value, ast.Name) and node.func.value.id == "matplotlib"):
            found.append((node.lineno, f"{name}:{node.lineno}: matplotlib.use()"))
    return [hit for _, hit in sorted(found)]


def test_no_module_switches_the_matplotlib_backend_or_uses_pyplot():
    found = [hit for pkg in PACKAGES for path in sorted((ROOT / pkg).rglob("*.py")) for hit in
             _pyplot_or_backend_calls(path.read_text(encoding="utf-8"), str(path.relative_to(ROOT)))]
    assert found == []
    probe = "import matplotlib\nmatplotlib.use('Agg')\nfrom matplotlib import pyplot\n"
    assert _pyplot_or_backend_calls(probe, "x.py") == ["x.py:2: matplotlib.use()", "x.py:3: imports pyplot"]


def test_figures_use_the_figure_api(tmp_path):
    import sys

    from emulator.report.figures import save, subplots

    had_pyplot = "matplotlib.pyplot" in sys.modules
    fig, axes = subplots(1, 2, figsize=(4, 2), sharey=True)
    axes[0].plot([0, 1], [0, 1])
    path = save(fig, tmp_path / "f.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert ("matplotlib.pyplot" in sys.modules) == had_pyplot
