"""Argument types every ``exposim`` sub-command shares: ``WxH`` sizes and comma-separated lists.

Each is an ``argparse`` ``type=`` callable: bad text becomes ``argparse.ArgumentTypeError``,
which argparse prints as a one-line usage error naming the option.
"""

from __future__ import annotations

import argparse

__all__ = ["size", "names", "ints", "floats", "seed", "positive_int", "SEED_MAX"]

#: Largest seed NumPy's legacy ``RandomState`` (Kim's optimizer restarts) takes: 2**32 - 1.
SEED_MAX = 2**32 - 1


def size(text: str) -> tuple[int, int]:
    """``"480x300"`` -> ``(480, 300)``; both positive."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 480x300, got {text!r}") from None
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"width and height must be positive, got {text!r}")
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
