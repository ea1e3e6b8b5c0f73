"""Tests of emulator/noise/."""
