"""The ``exposim`` command line.

Thin by design: every sub-command lives in a small module that parses its
arguments and calls one library function.  Sub-command modules expose
``register(subparsers)``, which adds their parsers and sets ``func`` on them.
Modules are imported only to build the parser; heavy libraries (Mitsuba,
colour-science, evo, matplotlib) are imported inside the command functions.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from emulator.errors import ExposimError

__all__ = ["main", "build_parser"]

#: Modules that contribute sub-commands, in the order they appear in ``--help``.
COMMAND_MODULES = (
    "emulator._cli.core",  # info, emulate, demo
    "emulator._cli.run",  # run
    "emulator._cli.calibrate",  # calibrate
    "emulator._cli.bench",  # bench features|vo|rpe
    "scenes.cli",  # render
    "scenes.synth_cli",  # synth
    "validation.cli",  # validate
)


def build_parser() -> argparse.ArgumentParser:
    from emulator import __version__

    parser = argparse.ArgumentParser(
        prog="exposim",
        description=(
            "Offline, reproducible auto-exposure benchmarking: emulate any exposure time "
            "from a bracketed recording (BorealHDR layout), run AE methods in closed loop, "
            "and validate everything on synthetic ground truth."
        ),
    )
    parser.add_argument("--version", action="version", version=f"exposim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:  # a sub-command not built yet
            if exc.name != name:
                raise
            continue
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        result = args.func(args)
    except (ExposimError, FileNotFoundError, FileExistsError, NotADirectoryError) as exc:
        print(f"exposim {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"exposim {args.command}: interrupted", file=sys.stderr)
        return 130
    return int(result or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
