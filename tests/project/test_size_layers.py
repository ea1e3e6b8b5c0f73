"""Size limits of the synthetic and validation layers (issue 23): ``scenes/``, ``synth/``, ``validation/``.

No module over 500 lines, no function over 100 lines of code, counted as ``tests/project/test_size.py``
counts them for ``emulator/`` (its checker is used here: lines without blank lines,
comment-only lines and the function's docstring; nested functions count in their parent too).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.project.test_size import MAX_FUNCTION_LOC, MAX_MODULE_LINES, offenders

ROOT = Path(__file__).resolve().parents[2]
LAYERS = ("scenes", "synth", "validation")

def test_layers_keep_their_size():
    bad = [o for layer in LAYERS for o in offenders(ROOT, layer)]
    assert bad == []


@pytest.mark.parametrize("layer", LAYERS)
def test_the_checker_reads_each_layer(layer, tmp_path):
    assert len(list((ROOT / layer).rglob("*.py"))) >= 10
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LOC))
    (tmp_path / layer / "deep").mkdir(parents=True)
    (tmp_path / layer / "deep" / "a.py").write_text(f"def f():\n{body}\n" + "\n" * MAX_MODULE_LINES)
    assert offenders(tmp_path, layer) == [
        f"{layer}/deep/a.py: {MAX_FUNCTION_LOC + 1 + MAX_MODULE_LINES} lines (> {MAX_MODULE_LINES})",
        f"{layer}/deep/a.py:1: f has {MAX_FUNCTION_LOC + 1} lines of code (> {MAX_FUNCTION_LOC})",
    ]
