"""Tests of emulator/orchestration/."""
