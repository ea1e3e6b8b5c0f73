"""Tests of emulator/core/."""
