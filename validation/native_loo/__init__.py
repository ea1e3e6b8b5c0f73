"""``exposim validate native SEQ``: native emulation checked by leaving each recorded frame out.

Package shape as every study: :mod:`.measure` (the numeric measurements), :mod:`.study` (its
configuration, runs it, writes ``results.json`` and ``report.md``), :mod:`.cli` (``exposim
validate native``).  Runs on real recordings; needs no synthetic-layer extra.
"""

from validation.native_loo.study import NativeLooConfig, run_study

__all__ = ["NativeLooConfig", "run_study"]
