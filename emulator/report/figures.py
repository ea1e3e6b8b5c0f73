"""Headless matplotlib figures: an Agg canvas without ``pyplot`` (no global backend, no window).

Every figure of :mod:`emulator.report` is made by :func:`new_figure` and written by
:func:`save`, which goes through :func:`emulator.io.files.save_figure` (atomic PNG).
"""

from __future__ import annotations

import os
from pathlib import Path

from emulator.io.files import save_figure

__all__ = ["new_figure", "subplots", "save", "plural", "same_as", "legend_outside", "log_ticks_at"]


def new_figure(ncols: int = 1, width: float = 5.0, height: float = 4.0, *, nrows: int = 1):
    """(figure, flat array of axes) of ``nrows`` x ``ncols`` panels, each ``width`` x ``height`` inches."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width * ncols, height * nrows), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    return fig, axes


def subplots(nrows: int = 1, ncols: int = 1, *, figsize=(6.4, 4.8), **kwargs):
    """``pyplot.subplots`` without ``pyplot``: (figure on an Agg canvas, axes as ``Figure.subplots`` gives them).

    ``kwargs`` go to :meth:`matplotlib.figure.Figure.subplots` (``sharex``, ``sharey``,
    ``squeeze``, ...); nothing touches matplotlib's global backend or figure manager.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def save(fig, path: str | os.PathLike, *, dpi: int = 110, overwrite: bool = True) -> Path:
    """Write the figure as PNG (atomically) and return the path."""
    return save_figure(fig, path, dpi=dpi, overwrite=overwrite)


def plural(n: int, word: str, words: str | None = None) -> str:
    """``"1 frame"``, ``"2 frames"``, ``"0 frames"``.

    >>> plural(1, "frame"), plural(3, "frame"), plural(0, "pass", "passes")
    ('1 frame', '3 frames', '0 passes')
    """
    return f"{n} {word if n == 1 else (words or word + 's')}"


def same_as(curves: dict) -> dict[str, str]:
    """For each curve identical to an earlier one (same values, NaN equal to NaN), that earlier name.

    >>> same_as({"a": [1, 2], "b": [1, 3], "c": [1, 2], "d": [1, 2]})
    {'c': 'a', 'd': 'a'}
    """
    import numpy as np

    seen: list[tuple[str, object]] = []
    out = {}
    for name, values in curves.items():
        arr = np.asarray(values, dtype=float)
        twin = next((n for n, v in seen if v.shape == arr.shape and np.array_equal(v, arr, equal_nan=True)), None)
        if twin is None:
            seen.append((name, arr))
        else:
            out[name] = twin
    return out


def legend_outside(ax, **kwargs):
    """A legend to the right of the axes, never over the data (constrained layout makes room)."""
    if not ax.get_legend_handles_labels()[0]:
        return None
    kwargs.setdefault("fontsize", "small")
    return ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, **kwargs)


def log_ticks_at(ax, values, *, axis: str = "y", unit: str = "", data=None) -> list[float]:
    """Label a log axis at ``values`` (e.g. the brackets, 1, 2, 4 ... 32 ms) instead of powers of ten.

    With ``data``, ticks are added below the smallest value by halving it until one is at or below
    the data's minimum, and the axis is extended to show that tick, so the data's lowest point
    always has a labelled tick at or below it (a method at 0.5 ms beside brackets from 1 ms gets a
    0.5 tick).  Minor tick labels are switched off, so no labels collide.  Returns the ticks.

    >>> from emulator.report.figures import new_figure
    >>> fig, (ax,) = new_figure()
    >>> _ = ax.plot([0, 1], [0.6, 20]); ax.set_yscale("log")
    >>> log_ticks_at(ax, [1, 2, 4, 8, 16, 32], data=[0.6, 20])
    [0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0]
    """
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    values = sorted({float(v) for v in values if v and v > 0})
    if not values:
        return []
    lows = [float(v) for v in (data if data is not None else []) if v is not None and 0 < v < float("inf")]
    lo = min(lows, default=values[0])
    while values[0] > lo:
        values.insert(0, values[0] / 2)
    target = ax.yaxis if axis == "y" else ax.xaxis
    target.set_major_locator(FixedLocator(values))
    target.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:.3g}{unit}"))
    target.set_minor_formatter(NullFormatter())
    if lows:
        get, set_ = (ax.get_ylim, ax.set_ylim) if axis == "y" else (ax.get_xlim, ax.set_xlim)
        bottom, top = get()
        if bottom > values[0] / 1.1:
            set_(values[0] / 1.1, top)
    return values
