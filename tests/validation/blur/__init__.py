"""Tests of validation/blur/."""
