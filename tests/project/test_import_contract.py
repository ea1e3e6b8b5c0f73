"""The import contract of DESIGN.md: ``validation -> scenes -> synth -> emulator``, and the floors inside.

Every module of the four packages is parsed (not imported) and every import is read,
including imports inside functions, relative imports and ``importlib.import_module("...")``
/ ``__import__("...")`` with a literal name.  A package may import only itself and the
packages below it, so ``emulator`` (what real-data users install and run) never reaches
``synth``, ``scenes`` or ``validation``, not even lazily; and Mitsuba / Dr.Jit are
imported only inside ``scenes/``.

Inside a package the same rule holds between its floors (:data:`FLOORS`): each top-level
module or sub-package of the package sits on one floor and imports only its own floor and those
below.  The package's ``__init__`` (its public facade) is the top floor: it may import any floor
and nothing inside the package imports it.

The checker is tested on small synthetic trees too, so that this test can fail.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: Lowest first: a package may import the ones before it in this tuple, never those after.
LAYERS = ("emulator", "synth", "scenes", "validation")
#: Third-party top-level modules allowed only inside one package.
CONFINED = {"mitsuba": "scenes", "drjit": "scenes"}
#: Inside a package, lowest first: the top-level modules and sub-packages on each floor.
FLOORS = {
    "emulator": (
        ("errors", "version", "extras", "cells", "pools", "numpy_dispatch"),  # base: no numbers, no files
        ("core", "noise", "autoexposure"),  # numeric core: arrays in, arrays out
        ("io",),  # files: recordings, run folders, caches
        ("report", "metrics", "calibration"),  # what a run or a recording measures and says
        ("playback",),  # the closed loop and its image providers
        ("orchestration",),  # orchestration: run folders, dataset runs, Dask, interrupts
        ("commands",),  # the command line
    ),
    "validation": (
        ("common", "published", "protocol", "demo"),  # base: shared helpers, published data, the study protocol
        ("verdicts",),  # statistics of the verdicts: tables in, verdicts out
        ("emulation", "selectors", "motion", "speed", "calibration_study", "render_study", "native_loo",
         "ae_study"),  # studies on their own
        ("report", "live"),  # studies built on others: the four experiments' runner, live (reads the AE study's)
        ("blur", "verdict_studies"),  # studies built on live: blur's live-against-emulated, checks of its folders
        ("commands",),  # the command line: the registry of studies
    ),
    "synth": (
        ("errors", "pose", "response_fit"),  # base: errors, the pose check, a response fit
        ("presets", "procedural", "camera", "sensor", "noise_model", "imaging"),  # the forward camera model
        ("source", "dataset", "sequence"),  # capture: radiance sources, bracket cycles, the dataset writer
    ),
    "scenes": (
        ("errors", "cache", "variant", "texture_base", "geometry", "lighting", "camera", "denoise",
         "render_interrupts"),  # base: no Mitsuba scene yet
        ("description", "textures", "dynamic_range", "trajectory", "walks", "adaptive",
         "mitsuba_objects"),  # what a scene is: its description, textures, light, paths
        ("base", "library", "presets"),  # scenes and render presets
        ("render", "parallel", "spp", "blur", "walkshots"),  # rendering
        ("synthesize", "image_stats"),  # renders through the synthetic camera, their statistics
        ("commands",),  # the command line
    ),
}


def module_name(path: Path, root: Path) -> tuple[str, bool]:
    """Dotted name of a source file under ``root`` and whether it is a package ``__init__``."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    is_package = parts[-1] == "__init__"
    if is_package:
        parts = parts[:-1]
    return ".".join(parts), is_package


def imports_of(source: str, name: str, is_package: bool) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in ``source``, wherever it sits."""
    package = name if is_package else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.append((node.lineno, target))
            # "from pkg import module" names a module too
            found += [(node.lineno, f"{target}.{alias.name}" if target else alias.name)
                      for alias in node.names if alias.name != "*"]
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            func = node.func
            called = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
            if called in ("import_module", "__import__"):
                found.append((node.lineno, node.args[0].value))
    return found


def violations(root: Path, layers=LAYERS, confined=CONFINED) -> list[str]:
    """Every import that breaks the contract, as ``path:line: A imports B``."""
    rank = {pkg: i for i, pkg in enumerate(layers)}
    bad = []
    for pkg in layers:
        for path in sorted((root / pkg).rglob("*.py")):
            name, is_package = module_name(path, root)
            for line, target in imports_of(path.read_text(encoding="utf-8"), name, is_package):
                top = target.split(".")[0]
                where = f"{path.relative_to(root)}:{line}"
                if top in rank and rank[top] > rank[pkg]:
                    bad.append(f"{where}: {pkg} imports {target} (allowed: {', '.join(layers[: rank[pkg] + 1])})")
                if top in confined and confined[top] != pkg:
                    bad.append(f"{where}: {pkg} imports {target} ({top} only inside {confined[top]}/)")
    return bad


def test_the_packages_keep_the_dependency_direction():
    assert violations(ROOT) == []


def floor_violations(root: Path, floors=FLOORS) -> list[str]:
    """Every import inside a package that climbs a floor (or reaches the package's facade)."""
    bad = []
    for pkg, levels in floors.items():
        rank = {unit: i for i, units in enumerate(levels) for unit in units}
        top = len(levels)

        def floor_of(name: str) -> int | None:
            parts = name.split(".")
            if parts[0] != pkg:
                return None
            if len(parts) == 1:
                return top  # the facade
            if parts[1] in rank:
                return rank[parts[1]]
            exists = (root / pkg / parts[1]).is_dir() or (root / pkg / f"{parts[1]}.py").is_file()
            return -1 if exists else None  # -1: a unit on no floor; None: a name, not a module

        for path in sorted((root / pkg).rglob("*.py")):
            name, is_package = module_name(path, root)
            here = floor_of(name)
            where = path.relative_to(root)
            if here == -1:
                bad.append(f"{where}: {name} is on no floor of {pkg} (add it to FLOORS)")
                continue
            seen = set()
            found = imports_of(path.read_text(encoding="utf-8"), name, is_package)
            for line, target in found:
                there = floor_of(target)
                if there == top:  # ``from pkg import module, ...`` asks for modules, not the facade
                    named = [t for ln, t in found if ln == line and t.startswith(f"{pkg}.")]
                    if named and all(floor_of(t) is not None and t.count(".") == 1 for t in named):
                        continue
                if there is None or here == top or there == -1 or line in seen:
                    continue
                if there > here:
                    level = "the facade" if there == top else f"floor {there} ({', '.join(levels[there])})"
                    bad.append(f"{where}:{line}: {name} (floor {here}) imports {target}, on {level}")
                    seen.add(line)
    return bad


def test_no_import_climbs_a_floor_inside_a_package():
    assert floor_violations(ROOT) == []


def test_every_folder_and_module_of_a_floored_package_is_on_a_floor():
    for pkg, levels in FLOORS.items():
        placed = {unit for units in levels for unit in units}
        here = {p.stem for p in (ROOT / pkg).glob("*.py") if p.stem != "__init__"}
        here |= {p.name for p in (ROOT / pkg).iterdir() if (p / "__init__.py").is_file()}
        assert here == placed, (sorted(here - placed), sorted(placed - here))


def test_the_floor_checker_finds_a_climb_and_the_facade(tmp_path):
    floors = {"emulator": (("errors",), ("core",), ("io",))}
    root = _tree(tmp_path, {
        "emulator/errors.py": "",
        "emulator/core/__init__.py": "",
        "emulator/core/a.py": "from emulator.errors import E\ndef f():\n    from emulator.io.png import read\n",
        "emulator/io/__init__.py": "",
        "emulator/io/png.py": "from emulator.core import a\nfrom emulator import __version__\nfrom emulator import core\n",
        "emulator/loose.py": "",
    })
    found = floor_violations(root, floors)
    assert found == [
        "emulator/core/a.py:3: emulator.core.a (floor 1) imports emulator.io.png, on floor 2 (io)",
        "emulator/io/png.py:2: emulator.io.png (floor 2) imports emulator, on the facade",
        "emulator/loose.py: emulator.loose is on no floor of emulator (add it to FLOORS)",
    ]


def test_every_package_is_checked():
    for pkg in LAYERS:
        assert (ROOT / pkg / "__init__.py").is_file()
        assert len(list((ROOT / pkg).rglob("*.py"))) > 3, pkg


# ------------------------------------------------------------------- the checker itself
def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for pkg in LAYERS:
        (tmp_path / pkg).mkdir(exist_ok=True)
        (tmp_path / pkg / "__init__.py").write_text("")
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    return tmp_path


def test_checker_accepts_downward_and_internal_imports(tmp_path):
    root = _tree(tmp_path, {
        "validation/a.py": "import scenes\nfrom synth import camera\nfrom emulator.io import png\n",
        "scenes/r.py": "def f():\n    import mitsuba as mi\n    from . import base\n    from .base import x\n",
        "synth/s.py": "from emulator.core.response import CameraResponse\nimport numpy\n",
        "emulator/io/p.py": "from ..errors import DatasetError\nfrom . import files\n",
    })
    assert violations(root) == []


@pytest.mark.parametrize("rel, text, expected", [
    ("emulator/commands/cli.py", "def main():\n    from validation.commands import validate\n",
     "emulator/commands/cli.py:2: emulator imports validation.commands"),
    ("emulator/x.py", "import scenes.render as r\n", "emulator/x.py:1: emulator imports scenes.render"),
    ("emulator/x.py", "import importlib\nm = importlib.import_module('synth.camera')\n",
     "emulator/x.py:2: emulator imports synth.camera"),
    ("synth/y.py", "class C:\n    def f(self):\n        from scenes import cache\n",
     "synth/y.py:3: synth imports scenes"),
    ("scenes/z.py", "if True:\n    from validation import common\n", "scenes/z.py:2: scenes imports validation"),
    ("synth/m.py", "def f():\n    import mitsuba\n", "synth/m.py:2: synth imports mitsuba (mitsuba only inside scenes/)"),
    ("validation/d.py", "from drjit import llvm\n", "validation/d.py:1: validation imports drjit (drjit only"),
    ("emulator/sub/__init__.py", "from ... import scenes\n", "emulator/sub/__init__.py:1: emulator imports scenes"),
])
def test_checker_finds_an_upward_or_confined_import(tmp_path, rel, text, expected):
    found = violations(_tree(tmp_path, {rel: text}))
    assert found and found[0].startswith(expected), found


def test_relative_imports_resolve_against_the_package():
    assert imports_of("from ..errors import E\n", "emulator.io.png", False)[0] == (1, "emulator.errors")
    assert imports_of("from . import png\n", "emulator.io", True) == [(1, "emulator.io"), (1, "emulator.io.png")]
    assert imports_of("from .x import y\n", "scenes.commands.render", False)[0] == (1, "scenes.commands.x")


# ------------------------------------------------------------------- no circles between modules
def _is_type_checking(node) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def runtime_imports(source: str, name: str, is_package: bool, modules) -> set[str]:
    """The modules (of ``modules``) that ``source`` imports when it runs, lazily included.

    ``from a.b import f`` imports ``a.b``; ``from a import b`` (``b`` a module) imports
    ``a.b`` and not ``a`` itself (Python runs the parent packages first whatever is asked; that
    is not what the code asked for).  Imports under ``if TYPE_CHECKING:`` never run and are
    left out (annotations only).
    """
    package = name if is_package else name.rpartition(".")[0]
    found: set[str] = set()

    def owner(target: str) -> str | None:
        parts = target.split(".")
        while parts and ".".join(parts) not in modules:
            parts.pop()
        return ".".join(parts) or None

    def visit(node) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            found.update(filter(None, (owner(alias.name) for alias in node.names)))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for alias in node.names:
                sub = f"{target}.{alias.name}" if target else alias.name
                found.update(filter(None, [sub if sub in modules else owner(target)]))
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            func = node.func
            if (func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)) in (
                    "import_module", "__import__"):
                found.update(filter(None, [owner(node.args[0].value)]))
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(source))
    found.discard(name)
    return found


def module_graph(root: Path, layers=LAYERS) -> dict[str, set[str]]:
    """Module -> the modules of the four packages it imports at run time (:func:`runtime_imports`)."""
    files = {}
    for pkg in layers:
        for path in sorted((root / pkg).rglob("*.py")):
            files[module_name(path, root)[0]] = path
    return {name: runtime_imports(path.read_text(encoding="utf-8"), name, path.name == "__init__.py", files)
            for name, path in files.items()}


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:  # iterative enough for a few hundred modules
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def test_no_import_circles_between_modules():
    cycles = import_cycles(module_graph(ROOT))
    assert cycles == [], "\n".join(" <-> ".join(c) for c in cycles)


def test_the_cycle_checker_finds_a_lazy_circle(tmp_path):
    root = _tree(tmp_path, {
        "emulator/a.py": "from emulator.b import f\n",
        "emulator/b.py": "def f():\n    from emulator import a\n",
        "emulator/c.py": "from emulator.a import g\nimport emulator.errors\nfrom emulator import d\n",
        "emulator/d.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from emulator.c import g\n",
        "emulator/errors.py": "",
    })
    graph = module_graph(root)
    assert graph["emulator.c"] == {"emulator.a", "emulator.errors", "emulator.d"}  # not the package emulator
    assert graph["emulator.d"] == set()  # annotations only
    assert import_cycles(graph) == [["emulator.a", "emulator.b"]]
    (root / "emulator/b.py").write_text("def f():\n    pass\n")
    assert import_cycles(module_graph(root)) == []
