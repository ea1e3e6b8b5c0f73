"""Calibration study configuration: the presets, the DN range, the ``full`` and ``quick`` :data:`CONFIGS`."""

from __future__ import annotations

__all__ = ["PRESETS", "DN_RANGE", "CONFIGS", "SHOT_INTERVAL_S", "BRACKETS_MS"]

PRESETS = ("borealhdr", "linear", "gamma22", "s_curve")
DN_RANGE = (16, 4079)
#: Full and quick configurations.
CONFIGS = {
    "full": {"width": 320, "height": 200, "n_exposures": 40, "spp": 16, "max_pixels": 65536,
             "insitu_width": 320, "insitu_height": 200, "insitu_sweeps": 12, "geometric_control": True,
             "als_control": True, "real_sample": True},
    "quick": {"width": 160, "height": 100, "n_exposures": 16, "spp": 4, "max_pixels": 16000,
              "insitu_width": 160, "insitu_height": 100, "insitu_sweeps": 4, "geometric_control": False,
              "als_control": False, "real_sample": True},
}
SHOT_INTERVAL_S = 1.0 / 22.0
BRACKETS_MS = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
