"""The sub-commands of ``exposim`` that run emulator code: info, emulate, run, calibrate, bench.

Each module has ``register(subparsers)``, declared in pyproject.toml under the entry-point
group ``exposim.commands`` (one entry per top-level command), and each command only parses
its arguments, calls the library and prints.  The dispatcher is :mod:`emulator.commands.cli`.
A command's ``register`` module holds its arguments only; what the command runs sits in
``NAME_body.py``, named by :class:`~emulator.commands.body.CommandBody` and imported when the
command runs, so ``exposim --help`` does not import every command's dependencies.
"""
