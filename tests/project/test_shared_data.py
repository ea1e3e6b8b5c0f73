"""Tests that need ``../shared`` skip where it is absent, and fail under CI (issue 46): a CI run must not pass
a weaker suite without a word."""

from __future__ import annotations

import pytest

from tests.conftest import in_ci, missing_shared


@pytest.mark.parametrize("value, ci", [("true", True), ("1", True), ("TRUE", True), ("", False), ("false", False)])
def test_ci_is_read_from_the_environment(monkeypatch, value, ci):
    monkeypatch.setenv("CI", value)
    assert in_ci() is ci


def test_missing_shared_data_fails_under_ci_and_skips_elsewhere(monkeypatch):
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI is set: the shared data must be present"):
        missing_shared("shared BorealHDR sample not found at /nowhere")
    monkeypatch.delenv("CI")
    with pytest.raises(pytest.skip.Exception, match="not found at /nowhere"):
        missing_shared("shared BorealHDR sample not found at /nowhere")
