"""Tests of scenes/."""
