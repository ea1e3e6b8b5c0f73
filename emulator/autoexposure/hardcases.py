"""The hard-case set every AE method must survive (finite output inside its range).

Black frame, fully saturated frame, flat frames at several levels, a single bright pixel,
a frame with one column of noise; the "same frame repeated 100 times" case is a loop over
any of these (see the tests).
"""

from __future__ import annotations

import numpy as np

from emulator.autoexposure.base import MAX_DN

__all__ = ["hard_cases", "FLAT_LEVELS"]

#: DN levels of the flat frames (black and white included).
FLAT_LEVELS = (0, 1, 100, 1120, 2048, 3040, 4000, MAX_DN - 1, MAX_DN)


def hard_cases(shape: tuple[int, int] = (48, 64), *, white_level: int = MAX_DN, seed: int = 0) -> dict[str, np.ndarray]:
    """name -> uint16 mosaic of the hard-case set (deterministic for a seed)."""
    h, w = shape
    rng = np.random.default_rng(seed)
    cases: dict[str, np.ndarray] = {
        "black": np.zeros(shape, np.uint16),
        "saturated": np.full(shape, white_level, np.uint16),
    }
    for level in FLAT_LEVELS:
        if level <= white_level:
            cases[f"flat-{level}"] = np.full(shape, level, np.uint16)
    one = np.zeros(shape, np.uint16)
    one[h // 2, w // 2] = white_level
    cases["single-bright-pixel"] = one
    col = np.zeros(shape, np.uint16)
    col[:, w // 3] = rng.integers(0, white_level + 1, size=h, dtype=np.uint16)
    cases["noise-column"] = col
    mid = np.full(shape, 2048, np.uint16)
    mid[:, w // 3] = rng.integers(0, white_level + 1, size=h, dtype=np.uint16)
    cases["noise-column-on-gray"] = mid
    return cases
