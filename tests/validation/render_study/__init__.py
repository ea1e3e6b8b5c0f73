"""Tests of validation/render_study/."""
