"""Two house rules on imports, read from the source (parsed, not imported).

- **No private name crosses a module.**  ``from emulator.x import _helper`` (or from a private
  module, ``emulator.x._impl``) means a seam without a public name: what another module
  imports is public in its home module.  Budget: none.
- **A module's dependencies are read from its top.**  Own-package imports inside function
  bodies are kept only beside an optional heavy dependency or to break an import circle, with
  a comment saying which; each package has a budget (:data:`BUDGET`), checked for the packages
  in :data:`CHECKED`.

The checkers are tested on small synthetic trees too, so that these tests can fail.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: Every package of the repository whose imports are read.
PACKAGES = ("emulator", "synth", "scenes", "validation", "scripts", "benchmarks")
#: Own-package import statements allowed inside function bodies, per package.
#: Both are at none today; a new one beside an optional heavy dependency raises its budget here, with its reason.
BUDGET = {"emulator": 0, "validation": 0}
#: The packages whose budget is checked.
CHECKED = ("emulator", "validation")


def _private(part: str) -> bool:
    return part.startswith("_") and not part.startswith("__")


def _source_files(root: Path, packages) -> list[Path]:
    return [p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))]


def private_imports(root: Path, packages=PACKAGES) -> list[str]:
    """Every import of a private name or from a private module of ``packages``: ``path:line: text``."""
    found = []
    for path in _source_files(root, packages):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                parts = node.module.split(".")
                if parts[0] not in packages:
                    continue
                bad = any(_private(p) for p in parts) or any(_private(a.name) for a in node.names)
            elif isinstance(node, ast.Import):
                bad = any(a.name.split(".")[0] in packages and any(_private(p) for p in a.name.split("."))
                          for a in node.names)
            else:
                continue
            if bad:
                found.append(f"{path.relative_to(root).as_posix()}:{node.lineno}: {ast.unparse(node)}")
    return found


def in_function_imports(root: Path, package: str) -> list[str]:
    """Every import of ``package`` itself inside a function body of ``package``, once each: ``path:line: text``."""
    found = []
    for path in _source_files(root, (package,)):
        seen = set()
        for fn in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if id(node) in seen or not isinstance(node, (ast.Import, ast.ImportFrom)):
                    continue
                seen.add(id(node))
                if isinstance(node, ast.ImportFrom):
                    own = node.level > 0 or (node.module or "").split(".")[0] == package
                else:
                    own = any(a.name.split(".")[0] == package for a in node.names)
                if own:
                    found.append(f"{path.relative_to(root).as_posix()}:{node.lineno}: {ast.unparse(node)}")
    return found


def test_no_private_name_crosses_a_module():
    assert private_imports(ROOT) == []


@pytest.mark.parametrize("package", CHECKED)
def test_own_package_imports_inside_functions_keep_to_the_budget(package):
    found = in_function_imports(ROOT, package)
    assert len(found) <= BUDGET[package], "\n".join(found)


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return tmp_path


def test_the_private_import_checker_finds_names_and_modules(tmp_path):
    root = _tree(tmp_path, {
        "emulator/__init__.py": "from emulator.version import __version__\n",
        "emulator/a.py": "def _helper():\n    pass\ndef helper():\n    pass\n",
        "emulator/b.py": ("from emulator.a import _helper\n"
                          "from emulator.a import helper as _helper2\n"
                          "from emulator._impl import thing\n"
                          "import emulator._impl\n"
                          "import os._private_ok\n"
                          "from numpy import _core\n"
                          "def f():\n    from emulator import _impl\n"),
        "emulator/_impl.py": "thing = 1\n",
        "scripts/s.py": "from emulator.a import _helper\n",
    })
    assert private_imports(root, packages=("emulator", "scripts")) == [
        "emulator/b.py:1: from emulator.a import _helper",
        "emulator/b.py:3: from emulator._impl import thing",
        "emulator/b.py:4: import emulator._impl",
        "emulator/b.py:8: from emulator import _impl",
        "scripts/s.py:1: from emulator.a import _helper",
    ]
    (root / "emulator/b.py").write_text("from emulator.a import helper\nfrom emulator.version import __version__\n")
    (root / "scripts/s.py").write_text("from emulator.a import helper as _helper\n")
    assert private_imports(root, packages=("emulator", "scripts")) == []


def test_the_in_function_checker_counts_each_own_import_once(tmp_path):
    root = _tree(tmp_path, {
        "emulator/a.py": ("from emulator.errors import E\n"
                          "import numpy\n"
                          "def f():\n"
                          "    import matplotlib\n"
                          "    from emulator.io import png\n"
                          "    def g():\n"
                          "        import emulator.core.blur as blur\n"
                          "    return g\n"
                          "class C:\n"
                          "    def m(self):\n"
                          "        from . import b\n"
                          "        from synth import x\n"),
        "emulator/b.py": "X = 1\n",
    })
    assert in_function_imports(root, "emulator") == [
        "emulator/a.py:5: from emulator.io import png",
        "emulator/a.py:7: import emulator.core.blur as blur",
        "emulator/a.py:11: from . import b",
    ]
    (root / "emulator/a.py").write_text("from emulator.io import png\ndef f():\n    import matplotlib\n")
    assert in_function_imports(root, "emulator") == []


def test_every_budget_names_a_package_and_the_checked_ones_have_one():
    assert set(BUDGET) <= set(PACKAGES) and set(CHECKED) <= set(BUDGET)
