"""Tests of emulator/autoexposure/."""
