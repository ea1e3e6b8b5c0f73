"""Size limits of ``emulator/``: no module over 500 lines, no function over 100 lines of code.

A function's lines of code are its lines without blank lines, comment-only lines and its
docstring (nested functions count in their parent too).  The checker is run on small
synthetic sources as well, so that it can fail.
"""

from __future__ import annotations

import ast
import io
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MAX_MODULE_LINES = 500
MAX_FUNCTION_LOC = 100


def code_lines(source: str) -> set[int]:
    """Line numbers that hold code (not blank, not only a comment)."""
    lines = set()
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type in (tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT,
                        tokenize.ENDMARKER):
            continue
        lines.update(range(tok.start[0], tok.end[0] + 1))
    return lines


def function_sizes(source: str) -> list[tuple[str, int, int]]:
    """(qualified name, first line, lines of code) of every function in ``source``."""
    tree = ast.parse(source)
    code = code_lines(source)
    out = []

    def visit(node, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = set(range(child.lineno, child.end_lineno + 1)) & code
                body = child.body
                if body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant) \
                        and isinstance(body[0].value.value, str):
                    lines -= set(range(body[0].lineno, body[0].end_lineno + 1))
                out.append((f"{prefix}{child.name}", child.lineno, len(lines)))
                visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            else:
                visit(child, prefix)

    visit(tree, "")
    return out


def offenders(root: Path, package: str = "emulator") -> list[str]:
    bad = []
    for path in sorted((root / package).rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        source = path.read_text(encoding="utf-8")
        n = source.count("\n") + (0 if source.endswith("\n") or not source else 1)
        if n > MAX_MODULE_LINES:
            bad.append(f"{rel}: {n} lines (> {MAX_MODULE_LINES})")
        for name, line, loc in function_sizes(source):
            if loc > MAX_FUNCTION_LOC:
                bad.append(f"{rel}:{line}: {name} has {loc} lines of code (> {MAX_FUNCTION_LOC})")
    return bad


#: Offenders allowed for now: none (blur, metrics/stereo and metrics/bench were split along their
#: seams: emulator/core/gyro.py, metrics/stereo_calibration.py, metrics/vo_bench.py and
#: metrics/bench_common.py).  A new offender fails the test.
KNOWN_OFFENDERS: frozenset[str] = frozenset()


def _key(offence: str) -> str:
    path, _, rest = offence.partition(":")
    if rest.startswith(" "):  # "path: N lines"
        return path
    return f"{path}:{rest.split(': ', 1)[1].split(' ', 1)[0]}"  # "path:line: name has ..."


def test_emulator_modules_and_functions_keep_their_size():
    bad = [o for o in offenders(ROOT) if _key(o) not in KNOWN_OFFENDERS]
    assert bad == []


def test_the_size_checker_counts_code_only(tmp_path):
    body = "\n".join(f"    x{i} = {i}  # c" for i in range(MAX_FUNCTION_LOC - 1))
    ok = f'def f():\n    """Doc.\n\n    more\n    """\n    # only a comment\n\n{body}\n    return 0\n'
    assert function_sizes(ok) == [("f", 1, MAX_FUNCTION_LOC + 1)]  # the def line and 100 statements
    (tmp_path / "emulator").mkdir()
    (tmp_path / "emulator" / "a.py").write_text(ok)
    assert offenders(tmp_path) == ["emulator/a.py:1: f has 101 lines of code (> 100)"]
    short = "class C:\n    def g(self):\n        return 1\n"
    assert function_sizes(short) == [("C.g", 2, 2)]
    (tmp_path / "emulator" / "a.py").write_text(short + "\n" * MAX_MODULE_LINES)
    assert offenders(tmp_path) == [f"emulator/a.py: {MAX_MODULE_LINES + 3} lines (> {MAX_MODULE_LINES})"]
    assert _key(offenders(tmp_path)[0]) == "emulator/a.py"
    assert _key("emulator/b.py:12: g has 130 lines of code (> 100)") == "emulator/b.py:g"
