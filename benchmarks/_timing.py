"""Timing shared by the benchmark scripts (run as ``python benchmarks/<script>.py``)."""

from __future__ import annotations

import statistics
import time
from pathlib import Path

__all__ = ["median_ms", "SHARED", "SAMPLE_SEQ"]


def _find_shared() -> Path:
    """``../shared`` beside the repository, or from a git worktree the first ``shared/`` above it."""
    repo = Path(__file__).resolve().parents[1]
    for parent in repo.parents:
        if (parent / "shared" / "data").is_dir():
            return parent / "shared"
    return repo.parent / "shared"


SHARED = _find_shared()
#: The shared BorealHDR sample sequence (default input of the benchmarks).
SAMPLE_SEQ = SHARED / "data" / "borealhdr_sample" / "backpack_2023-09-25-15-05-03"


def median_ms(fn, repeat: int) -> float:
    """Median wall time of ``repeat`` calls of ``fn()``, in milliseconds."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)
