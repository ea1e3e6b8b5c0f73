"""Tests of validation/ae_study/."""
