"""Tests of emulator/report/."""
