"""Tests of validation/commands/ (exposim validate, its study protocol)."""
