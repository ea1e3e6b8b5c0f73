"""Figures (matplotlib) and markdown reports; the library never prints.

* :mod:`~emulator.report.figures`: a headless figure (Agg canvas, no ``pyplot``) and saving
  it through :func:`emulator.io.files.save_figure`.
* :mod:`~emulator.report.run`: the run folder's summary, ``exposure.png`` and ``report.md``.
* :mod:`~emulator.report.bench`: the feature (Fig. 4) and VO (Fig. 6) benchmark figures and
  reports.
* :mod:`~emulator.report.calibration`: the plot of a recovered inverse response.

Matplotlib is imported only when a figure is drawn.
"""
