"""Orchestration over the numeric core: work that reads recordings and writes folders.

The numeric core (response, emulate, select, noise, calibration fits, metrics) touches no
file; :mod:`emulator.io` owns the formats; modules here combine the two.
"""
