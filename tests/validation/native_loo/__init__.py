"""Tests of validation/native_loo/."""
