"""What the reports call the run's settings: words a robotics researcher reads without the code.

The command line's spellings (``--mode paper``, ``--selector higher-no-sat``, the method
names) stay as they are; these phrases say what each one means, once, for every report.

>>> mode_words("paper")
"the paper's methods with the published code's defects corrected"
>>> selector_words("higher-no-sat")
"the paper's bracket selector (higher bracket unless saturated)"
>>> selector_words("my-rule")
'my-rule'
"""

from __future__ import annotations

__all__ = ["MODE_WORDS", "SELECTOR_WORDS", "mode_words", "selector_words"]

#: ``--mode`` values in words.
MODE_WORDS = {
    "paper": "the paper's methods with the published code's defects corrected",
    "borealhdr": "the published BorealHDR code, its defects included",
}

#: ``--selector`` values in words.
SELECTOR_WORDS = {
    "higher-no-sat": "the paper's bracket selector (higher bracket unless saturated)",
    "closest": "the bracket closest to the target in log exposure",
    "reference": "the published code's bracket rule (higher bracket unless it saturates more than the lower one)",
}


def mode_words(mode) -> str:
    """``--mode`` in words; an unknown value as given."""
    return MODE_WORDS.get(str(mode), str(mode))


def selector_words(name) -> str:
    """``--selector`` in words; an unknown value as given."""
    return SELECTOR_WORDS.get(str(name), str(name))
