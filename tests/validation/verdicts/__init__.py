"""Tests of validation/verdicts/."""
