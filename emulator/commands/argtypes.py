"""Argument types every ``exposim`` sub-command shares: ``WxH`` sizes and comma-separated lists.

Each is an ``argparse`` ``type=`` callable: bad text becomes ``argparse.ArgumentTypeError``,
which argparse prints as a one-line usage error naming the option.
"""

from __future__ import annotations

import argparse

__all__ = ["size", "names", "ints", "floats", "seed", "positive_int", "SEED_MAX", "MIN_SIDE_PX", "MAX_PIXELS",
           "refine_mode"]

#: Largest seed NumPy's legacy ``RandomState`` (Kim's optimizer restarts) takes: 2**32 - 1.
SEED_MAX = 2**32 - 1


#: Smallest image side: what every AE method accepts (3 x 3 gradient kernels need an interior),
#: so a recording written at any accepted size can be run.
MIN_SIDE_PX = 4
#: Largest image: four BorealHDR frames (1920 x 1200) of pixels, checked before anything is
#: allocated (a 100000x100000 render would need terabytes).
MAX_PIXELS = 4 * 1920 * 1200


def size(text: str) -> tuple[int, int]:
    """``"480x300"`` -> ``(480, 300)``; each side at least :data:`MIN_SIDE_PX`, at most
    :data:`MAX_PIXELS` pixels in all."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 480x300, got {text!r}") from None
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"width and height must be positive, got {text!r}")
    if w < MIN_SIDE_PX or h < MIN_SIDE_PX:
        raise argparse.ArgumentTypeError(f"width and height must be at least {MIN_SIDE_PX} pixels (the smallest image "
                                         f"an AE method accepts), got {text!r}")
    if w * h > MAX_PIXELS:
        raise argparse.ArgumentTypeError(f"{text!r} is {w * h / 1e6:.1f} megapixels; at most {MAX_PIXELS / 1e6:.1f} "
                                         "(four 1920x1200 frames)")
    return w, h


def names(text: str) -> tuple[str, ...]:
    """``"a, b,,c"`` -> ``("a", "b", "c")``."""
    return tuple(s.strip() for s in text.split(",") if s.strip())


def _numbers(text: str, kind, what: str) -> tuple:
    try:
        return tuple(kind(s) for s in names(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated {what}, got {text!r}") from None


def ints(text: str) -> tuple[int, ...]:
    """``"1,4,16"`` -> ``(1, 4, 16)``."""
    return _numbers(text, int, "integers")


def floats(text: str) -> tuple[float, ...]:
    """``"0.5,1.5"`` -> ``(0.5, 1.5)``."""
    return _numbers(text, float, "numbers")


def seed(text: str) -> int:
    """A random seed: an integer in 0 .. 2**32 - 1 (what every seeded generator here takes)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer seed in 0..{SEED_MAX}, got {text!r}") from None
    if not 0 <= value <= SEED_MAX:
        raise argparse.ArgumentTypeError(f"seed must be in 0..{SEED_MAX}, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """An integer >= 1 (a count: workers, group size, jobs)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value


def refine_mode(value: str):
    """``--refine-extrinsics``: ``auto`` or a number of stereo pairs (0 or more)."""
    if value.strip().lower() == "auto":
        return "auto"
    try:
        n = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected 'auto' or a number of stereo pairs, got {value!r}") from None
    if n < 0:
        raise argparse.ArgumentTypeError(f"expected 'auto', 0 or a positive number of stereo pairs, got {n}")
    return n
