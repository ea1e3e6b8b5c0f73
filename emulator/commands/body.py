"""A command's body named by its import path, imported when the command runs.

Each ``register(subparsers)`` of :mod:`emulator.commands` builds only its arguments and sets
``func=CommandBody("emulator.commands.NAME_body:FUNCTION")``: ``exposim --help`` loads every
command's ``register`` (entry points, :mod:`emulator.commands.cli`) but no command's body, so a
body module keeps its imports at the top of the file and ``--help`` stays fast.  The body is
named the way methods and commands are (``module:attribute``); a body that cannot be imported
raises its :class:`ImportError` when the command runs, where the dispatcher reports it.
"""

from __future__ import annotations

from pkgutil import resolve_name

__all__ = ["CommandBody"]


class CommandBody:
    """``func`` of a sub-command: ``CommandBody("pkg.module:function")(args)`` imports the module and calls it."""

    def __init__(self, path: str) -> None:
        module, sep, attr = path.partition(":")
        if not (module and sep and attr):
            raise ValueError(f"a command body is named 'module:function', got {path!r}")
        self.path = path

    def load(self):
        """The body function itself (its module imported)."""
        return resolve_name(self.path)

    def __call__(self, args) -> int:
        return self.load()(args)

    def __repr__(self) -> str:
        return f"CommandBody({self.path!r})"
