"""Shared fixtures: paths to ../shared (never copied into the repository)."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _find_shared() -> Path:
    """``../shared`` beside the repository; from a git worktree (``/work/wt/NAME``) the first
    ``shared/`` folder found further up, so the sample tests run there too instead of skipping."""
    for parent in REPO.parents:
        if (parent / "shared" / "data").is_dir():
            return parent / "shared"
    return REPO.parent / "shared"


SHARED = _find_shared()
SAMPLE = SHARED / "data" / "borealhdr_sample"
SAMPLE_SEQ = SAMPLE / "backpack_2023-09-25-15-05-03"
PCALIB = SAMPLE / "calibration" / "pcalib_inside1.txt"


@pytest.fixture(scope="session")
def sample_seq() -> Path:
    if not SAMPLE_SEQ.is_dir():
        pytest.skip(f"shared BorealHDR sample not found at {SAMPLE_SEQ}")
    return SAMPLE_SEQ


@pytest.fixture(scope="session")
def pcalib_path() -> Path:
    if not PCALIB.is_file():
        pytest.skip(f"shared pcalib file not found at {PCALIB}")
    return PCALIB
