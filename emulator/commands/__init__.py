"""The sub-commands of ``exposim`` that run emulator code: info, emulate, run, calibrate, bench.

Each module has ``register(subparsers)``, declared in pyproject.toml under the entry-point
group ``exposim.commands`` (one entry per top-level command), and each command only parses
its arguments, calls the library and prints.  The dispatcher is :mod:`emulator.commands.cli`.
"""
