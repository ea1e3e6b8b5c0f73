"""12-bit Bayer mosaic -> 8-bit grey: the one conversion for viewing and for the metrics.

``gray8 = clip(round((g - black_level) * 255 / (white_level - black_level)), 0, 255)`` with
``g = cv2.cvtColor(raw, cv2.COLOR_BayerRG2GRAY)`` (grey in DN, ``uint16``) and rounding half
to even.  The scale is fixed by the camera's levels, the same for every image: a
per-image normalisation would hide exactly the exposure effects the benchmarks measure.
The run's ``--save png8`` images and the feature / VO metrics both use
:func:`bayer_to_gray8`, so a png8 image equals the conversion of the png16 image.

The scale is applied through a 65536-entry table per (white, black) pair, built with the
float formula above, so the result is bit-identical to it.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from emulator.errors import MetricsError

__all__ = ["bayer_to_gray8", "gray8_table"]


@functools.lru_cache(maxsize=8)
def gray8_table(white_level: int, black_level: int) -> np.ndarray:
    """uint8 table over every uint16 grey value: the fixed linear scale of the DN range to 0..255."""
    g = np.arange(65536, dtype=np.float64)
    table = np.clip(np.rint((g - black_level) * (255.0 / (white_level - black_level))), 0, 255).astype(np.uint8)
    table.setflags(write=False)
    return table


def bayer_to_gray8(raw: np.ndarray, *, white_level: int, black_level: int) -> np.ndarray:
    """Convert a 12-bit RGGB Bayer mosaic to 8-bit grey by the camera's fixed linear scale.

    Parameters
    ----------
    raw : numpy.ndarray
        (H, W) ``uint16`` RGGB Bayer mosaic in digital numbers (DN), at least 2 x 2.
    white_level, black_level : int
        The camera's clip levels in DN; ``black_level`` maps to 0 and ``white_level`` to 255.

    Returns
    -------
    numpy.ndarray
        (H, W) ``uint8`` grey image (module docstring).

    Examples
    --------
    >>> int(bayer_to_gray8(np.full((4, 4), 4094, np.uint16), white_level=4094, black_level=0)[0, 0])
    255
    >>> int(bayer_to_gray8(np.full((4, 4), 2048, np.uint16), white_level=4095, black_level=0)[0, 0])
    128
    >>> int(bayer_to_gray8(np.full((4, 4), 64, np.uint16), white_level=4095, black_level=64)[0, 0])
    0
    """
    raw = np.asarray(raw)
    if raw.ndim != 2 or raw.dtype != np.uint16:
        raise MetricsError(f"bayer_to_gray8: raw must be a 2-D uint16 Bayer mosaic, got {raw.dtype} {raw.shape}")
    if raw.shape[0] < 2 or raw.shape[1] < 2:
        raise MetricsError(f"bayer_to_gray8: raw must be at least 2x2, got {raw.shape}")
    white_level, black_level = int(white_level), int(black_level)
    if not 0 <= black_level < white_level <= 65535:
        raise MetricsError(f"bayer_to_gray8: need 0 <= black_level < white_level, got {black_level}, {white_level}")
    gray = cv2.cvtColor(np.ascontiguousarray(raw), cv2.COLOR_BayerRG2GRAY)
    return np.take(gray8_table(white_level, black_level), gray)
