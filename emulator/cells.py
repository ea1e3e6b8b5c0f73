"""The cells of a report's tables, one way each (numeric core, no I/O).

* :func:`median_finite`: the median of the finite values of a sequence. ``None``, NaN and
  infinities are left out; with no finite value left (an empty sequence included) the result
  is ``None``, never NaN.
* :func:`format_number`: a number as text with a format spec, the one number formatter of the
  reports. A missing value (``None``) is :data:`MISSING` (``n/a``), or the ``missing`` text a
  report's committed tables print (``-``: :data:`DASH`, the run, bench and VO reports, whose
  notes say what a ``-`` cell means); a bool is ``yes``/``no``; anything that is not a number is
  its ``str``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

__all__ = ["MISSING", "DASH", "format_number", "median_finite"]

#: How a missing value prints by default.
MISSING = "n/a"
#: How a missing value prints in the tables whose notes explain a "-" cell (``format_number(..., missing=DASH)``).
DASH = "-"


def median_finite(values: Iterable) -> float | None:
    """The median of the finite values of ``values``; ``None`` where none is finite.

    >>> median_finite([3, None, float("nan"), 1, float("inf"), 2])
    2.0
    >>> median_finite([None, float("nan")]) is None
    True
    """
    kept = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return float(np.median(kept)) if kept else None


def format_number(value, spec: str = ".3g", missing: str = MISSING) -> str:
    """``value`` formatted as a float with ``spec`` (``format(float(value), spec)``); ``missing`` (default
    :data:`MISSING`) for ``None``, ``yes``/``no`` for a bool, ``str(value)`` for anything that is not a number.

    >>> format_number(0.012345), format_number(None), format_number(3, ".1f"), format_number(True)
    ('0.0123', 'n/a', '3.0', 'yes')
    >>> format_number(None, missing=DASH), format_number(12, "d", missing=DASH)
    ('-', '12')
    """
    if value is None:
        return missing
    if isinstance(value, bool):
        return "yes" if value else "no"
    try:
        return format(float(value), spec)
    except (TypeError, ValueError):
        if isinstance(value, (int, np.integer)):  # an integer spec ("d"), which a float refuses
            return format(int(value), spec)
        return str(value)
