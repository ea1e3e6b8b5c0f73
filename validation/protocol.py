"""The study protocol: what a study declares so that ``exposim validate NAME`` runs it.

A study is one :class:`Study`: its name, a one-line help, the extras it needs, a function
that adds its options to a parser and one that runs it from the parsed options (exit code).
Each study package exposes its own (``STUDY`` in its ``cli`` module) and pyproject.toml
registers it under the entry-point group ``exposim.studies``; ``exposim validate`` builds
one sub-command per registered study (:mod:`validation.commands.validate`), in the order
of the registry.  This module sits on validation's base floor and imports no study.

:class:`DefaultsFormatter` is the help formatter of studies whose option defaults come from
their configuration (``action.config_default``).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["Study", "DefaultsFormatter", "show_value"]


@dataclass(frozen=True)
class Study:
    """One study of ``exposim validate``.

    ``add_arguments(parser)`` adds the study's options; ``run(args)`` runs it from the parsed
    options and returns the exit code (bad input raises
    :class:`~emulator.errors.ExposimError`, which the command line prints as one line);
    ``extras`` are the optional extras checked before it runs; ``description`` (default: the
    help) heads its ``--help``; ``formatter_class`` formats that help.
    """

    name: str
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], object]
    run: Callable[[argparse.Namespace], int]
    extras: tuple[str, ...] = ("synth",)
    description: str | None = None
    formatter_class: type | None = None

    def register(self, subparsers) -> argparse.ArgumentParser:
        """Add the study as a sub-command of ``subparsers`` (``exposim validate``'s); return its parser."""
        kw = {} if self.formatter_class is None else {"formatter_class": self.formatter_class}
        parser = subparsers.add_parser(self.name, help=self.help, description=self.description or self.help, **kw)
        self.add_arguments(parser)
        parser.set_defaults(func=self.run, experiment=self.name, extras=self.extras)
        return parser


class DefaultsFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's default in ``--help``: the argparse default, or, for an option left at
    None, the experiment configuration's value (full and ``--quick``), looked up only when
    the help is shown (``action.config_default``)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "%(default)" in text or "(default" in text:
            return text
        lazy = getattr(action, "config_default", None)
        if lazy is not None:
            full, quick = (show_value(v) for v in lazy())
            shown = full if full == quick else f"{full}; with --quick: {quick}"
            return f"{text} (default: {shown.replace('%', '%%')})"
        if action.default is None or action.default is False or action.default is argparse.SUPPRESS:
            return text
        return text + " (default: %(default)s)"


def show_value(value) -> str:
    """A configuration value as ``--help`` shows it: tuples comma-separated, None as ``none``."""
    if isinstance(value, (tuple, list)):
        return ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value)
    return "none" if value is None else str(value)
