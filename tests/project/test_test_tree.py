"""The tests mirror the tree: every test file sits in ``tests/<path>/`` where ``<path>`` is a package or
subpackage of the repository (``tests/emulator/io/`` tests ``emulator/io/``), ``scripts`` or ``benchmarks``,
or ``project`` for tests of the project as a whole; none sits flat in ``tests/``.

Each folder of test files is a package (``__init__.py``): a test module is named by its path
(``tests.emulator.io.test_zip``), so two folders may hold the same basename and a helper is imported by that
name.  No test file is named after a tracker number or a session.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: Folders of the repository that hold code but are not packages; their tests go to tests/<name>/.
SCRIPT_FOLDERS = ("scripts", "benchmarks")
#: The folder for tests of the project as a whole (import contract, sizes, docs, packaging, ...).
PROJECT = "project"
#: A file name that names a tracker issue, a version of the house or a session instead of a subject.
TRACKER_NAME = re.compile(r"issue|session|(^|_)v?\d+(_|$)")


def _mirrors(root: Path, folder: tuple[str, ...]) -> bool:
    if folder == (PROJECT,):
        return True
    if len(folder) == 1 and folder[0] in SCRIPT_FOLDERS:
        return (root / folder[0]).is_dir()
    return bool(folder) and (root.joinpath(*folder) / "__init__.py").is_file()


def misplaced(root: Path) -> list[str]:
    """Each test file under ``root/tests`` that breaks the layout, with the reason, as one line."""
    tests = root / "tests"
    bad = []
    for path in sorted(tests.rglob("test_*.py")):
        rel = path.relative_to(tests)
        folder = rel.parts[:-1]
        if "__pycache__" in folder:
            continue
        where = f"tests/{rel.as_posix()}"
        if not folder:
            bad.append(f"{where}: flat in tests/; move it to the folder of the package it tests")
        elif not _mirrors(root, folder):
            bad.append(f"{where}: {'/'.join(folder)}/ is no package, subpackage or script folder of the "
                       f"repository (tests of the project as a whole go to tests/{PROJECT}/)")
        missing = [tests.joinpath(*folder[:i]) for i in range(len(folder) + 1)
                   if not (tests.joinpath(*folder[:i]) / "__init__.py").is_file()]
        if missing:
            bad.append(f"{where}: no __init__.py in {', '.join(p.relative_to(root).as_posix() + '/' for p in missing)}")
        if TRACKER_NAME.search(path.stem):
            bad.append(f"{where}: named after a tracker number or session; name it after its subject")
    return bad


def test_every_test_file_sits_in_the_folder_of_a_package_it_mirrors():
    assert misplaced(ROOT) == []


def test_the_checker_refuses_a_flat_file_a_folder_that_mirrors_nothing_and_a_tracker_name(tmp_path):
    (tmp_path / "emulator" / "io").mkdir(parents=True)
    (tmp_path / "emulator" / "__init__.py").write_text("")
    (tmp_path / "emulator" / "io" / "__init__.py").write_text("")
    (tmp_path / "scripts").mkdir()
    for folder in ("", "emulator", "emulator/io", "emulator/nosuch", "project", "scripts", "old"):
        (tmp_path / "tests" / folder).mkdir(parents=True, exist_ok=True)
        (tmp_path / "tests" / folder / "__init__.py").write_text("")
    good = ["emulator/io/test_zip.py", "emulator/test_cells.py", "project/test_size.py", "scripts/test_render.py"]
    for rel in good + ["test_flat.py", "emulator/nosuch/test_x.py", "old/test_y.py", "emulator/io/test_issue_47.py"]:
        (tmp_path / "tests" / rel).write_text("")
    (tmp_path / "emulator" / "core").mkdir()
    (tmp_path / "tests" / "emulator" / "core").mkdir()
    (tmp_path / "emulator" / "core" / "__init__.py").write_text("")
    (tmp_path / "tests" / "emulator" / "core" / "test_no_init.py").write_text("")

    bad = misplaced(tmp_path)
    assert [line.split(":")[0] for line in bad] == [
        "tests/emulator/core/test_no_init.py",
        "tests/emulator/io/test_issue_47.py",
        "tests/emulator/nosuch/test_x.py",
        "tests/old/test_y.py",
        "tests/test_flat.py",
    ]
    assert "no __init__.py in tests/emulator/core/" in bad[0]
    assert "tracker number" in bad[1]
    assert "emulator/nosuch/ is no package" in bad[2]
    assert "flat in tests/" in bad[4]
