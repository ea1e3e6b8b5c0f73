"""Tests of emulator/playback/."""
