"""Tests of emulator/io/."""
