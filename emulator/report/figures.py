"""Headless matplotlib figures: an Agg canvas without ``pyplot`` (no global backend, no window).

Every figure of :mod:`emulator.report` is made by :func:`new_figure` and written by
:func:`save`, which goes through :func:`emulator.io.files.save_figure` (atomic PNG).
"""

from __future__ import annotations

import os
from pathlib import Path

from emulator.io.files import save_figure

__all__ = ["new_figure", "save"]


def new_figure(ncols: int = 1, width: float = 5.0, height: float = 4.0, *, nrows: int = 1):
    """(figure, flat array of axes) of ``nrows`` x ``ncols`` panels, each ``width`` x ``height`` inches."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width * ncols, height * nrows), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    return fig, axes


def save(fig, path: str | os.PathLike, *, dpi: int = 110, overwrite: bool = True) -> Path:
    """Write the figure as PNG (atomically) and return the path."""
    return save_figure(fig, path, dpi=dpi, overwrite=overwrite)
