"""Tests of emulator/calibration/."""
