"""``exposim validate blur``: exposure-time integration against a brute-force reference,
its cost, the walk's angular rate against the real gyro, and emulated-against-live sharpness.

Package shape as every study: :mod:`.config` (sizes, full and quick), :mod:`.measure` (the
numeric measurements), :mod:`.study` (runs them, writes ``results.json``), :mod:`.report`
(``report.md``), :mod:`.cli` (``exposim validate blur`` and ``python -m validation.blur``).
"""

from validation.blur.config import BlurConfig
from validation.blur.study import run_study

__all__ = ["BlurConfig", "run_study"]
