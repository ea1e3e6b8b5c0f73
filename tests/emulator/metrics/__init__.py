"""Tests of emulator/metrics/."""
