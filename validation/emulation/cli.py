"""Command line of the emulation study: ``python -m validation.emulation OUT [options]``.

The same as ``exposim validate emulation -o OUT [options]`` (the options, their defaults and
the run live in :mod:`validation.commands.experiments` and :func:`validation.report.run_experiment`).
"""

from __future__ import annotations

import sys

__all__ = ["main"]


def main(argv=None) -> int:
    """``python -m validation.emulation OUT [options]``: ``exposim validate emulation -o OUT [options]``."""
    from emulator.commands.cli import main as exposim

    args = sys.argv[1:] if argv is None else list(argv)
    if args and not args[0].startswith("-"):
        args = ["-o", args[0], *args[1:]]
    return exposim(["validate", "emulation", *args])
