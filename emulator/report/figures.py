"""Headless matplotlib figures: an Agg canvas without ``pyplot`` (no global backend, no window).

Every figure of :mod:`emulator.report` is made by :func:`new_figure` and written by
:func:`save`, which goes through :func:`emulator.io.files.save_figure` (atomic PNG).
"""

from __future__ import annotations

import os
from pathlib import Path

from emulator.io.files import save_figure

__all__ = ["new_figure", "subplots", "save"]


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
