"""Tests of validation/live/."""
