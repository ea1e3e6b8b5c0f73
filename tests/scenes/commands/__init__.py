"""Tests of scenes/commands/."""
