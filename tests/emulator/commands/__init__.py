"""Tests of emulator/commands/."""
