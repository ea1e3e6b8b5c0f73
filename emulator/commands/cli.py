"""The ``exposim`` command line: a thin dispatcher over registered sub-commands.

Sub-commands are not known here.  Each package declares its own in pyproject.toml under
the entry-point group ``exposim.commands`` (one entry per top-level command, its value a
``register(subparsers)`` callable in the package whose code the command runs), so this
module imports nothing from ``synth``, ``scenes`` or ``validation``.  A ``register``
callable may carry an integer ``order`` attribute (lower first) that places its command in
``--help``; commands without one follow, by name.

A command that fails to load is reported by name: ``--help`` lists it as broken, running
it prints why, and running another command prints a one-line warning.

Errors become one line on stderr, ``exposim CMD: error: ...``, and exit code 1:
:class:`~emulator.errors.ExposimError` (bad input), any :class:`OSError` (a missing,
unreadable or unwritable path: the message names it), and a missing optional extra (a
command's ``extras`` default, checked before it runs, or a :class:`ModuleNotFoundError` of
an extra's module: ``pip install 'exposim[synth]'``).  Ctrl-C gives exit code 130; a
closed pipe on stdout (``exposim info SEQ | head -1``) ends quietly (exit code 1, as
Python's documentation on SIGPIPE recommends).
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass
from importlib import metadata

from emulator.errors import ExposimError
from emulator.extras import missing_extra_message, require
from emulator.orchestration.interrupts import watchdog
from emulator.version import __version__

__all__ = ["main", "build_parser", "load_commands", "ENTRY_POINT_GROUP", "Command"]

#: The entry-point group sub-commands register under.
ENTRY_POINT_GROUP = "exposim.commands"
#: Place in ``--help`` of commands whose register callable has no ``order``.
DEFAULT_ORDER = 1000


@dataclass
class Command:
    """One registered sub-command: its name, entry point, register callable or load error."""

    name: str
    value: str
    register: object = None
    error: str | None = None

    @property
    def order(self) -> int:
        return int(getattr(self.register, "order", DEFAULT_ORDER))


def load_commands(entry_points=None) -> list[Command]:
    """The registered commands, loaded and sorted for ``--help`` (broken ones kept, with their error).

    ``entry_points`` (for tests) replaces the installed ``exposim.commands`` entry points.
    """
    eps = metadata.entry_points(group=ENTRY_POINT_GROUP) if entry_points is None else entry_points
    commands: dict[str, Command] = {}
    for ep in eps:
        known = commands.get(ep.name)
        if known is not None:
            if known.value != ep.value:
                known.error = (f"registered twice, by {known.value} and {ep.value}; uninstall one of the "
                               "packages that provide it")
            continue
        cmd = Command(ep.name, ep.value)
        try:
            cmd.register = ep.load()
        except Exception as exc:  # a broken plugin: report it by name, never swallow it
            cmd.error = f"cannot load {ep.value}: {type(exc).__name__}: {exc}"
        else:
            if not callable(cmd.register):
                cmd.error = f"{ep.value} is not a register(subparsers) callable"
        commands[ep.name] = cmd
    ok = sorted((c for c in commands.values() if c.error is None), key=lambda c: (c.order, c.name))
    broken = sorted((c for c in commands.values() if c.error is not None), key=lambda c: c.name)
    return ok + broken


def _broken(cmd: Command):
    def run(args) -> int:
        raise ExposimError(f"this command is broken ({cmd.error})")

    return run


def build_parser(commands: list[Command] | None = None) -> argparse.ArgumentParser:
    """The ``exposim`` parser with every registered command (see :func:`load_commands`)."""
    commands = load_commands() if commands is None else commands
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
    for cmd in commands:
        if cmd.error is None:
            try:
                cmd.register(sub)
            except Exception as exc:
                cmd.error = f"{cmd.value} failed to register: {type(exc).__name__}: {exc}"
            else:
                if cmd.name in sub.choices:
                    continue
                cmd.error = f"{cmd.value} did not add a '{cmd.name}' command"
        if cmd.name in sub.choices:
            sub.choices[cmd.name].set_defaults(func=_broken(cmd))
        else:
            broken = sub.add_parser(cmd.name, help=f"(broken: {cmd.error})")
            broken.add_argument("args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)  # say why, whatever the arguments
            broken.set_defaults(func=_broken(cmd))
    parser.commands = commands  # what main() warns about
    return parser


def _os_error(exc: OSError) -> str:
    """One line naming the path of an OS error: ``PATH: Permission denied``."""
    if exc.filename is None:
        return str(exc)
    where = os.fsdecode(exc.filename)
    if exc.filename2 is not None:
        where += f" -> {os.fsdecode(exc.filename2)}"
    return f"{where}: {exc.strerror or type(exc).__name__}"


def _quiet_stdout() -> None:
    """After EPIPE: point stdout at devnull so the interpreter's final flush cannot fail."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout without a file descriptor (captured): nothing to do
        pass


import warnings as _warnings  # noqa: E402

_default_showwarning = _warnings.showwarning


class Terminated(KeyboardInterrupt):
    """SIGTERM (what batch schedulers send), handled like Ctrl-C: runs record "interrupted"."""


def _on_sigterm(signum, frame):
    raise Terminated()


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    """exposim's own warnings (a recording without an IMU, ...) as one ``exposim: warning:`` line,
    without the source line Python's default format adds; other libraries' warnings as usual."""
    if category.__module__.split(".")[0] == "emulator":
        print(f"exposim: warning: {message}", file=file or sys.stderr)
    else:
        _default_showwarning(message, category, filename, lineno, file, line)


def main(argv: list[str] | None = None) -> int:
    import signal
    import threading
    import warnings

    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _on_sigterm)

    shown = warnings.showwarning
    warnings.showwarning = _one_line_warning
    try:
        with watchdog(lambda: _command_name[0]):  # Ctrl-C / SIGTERM end the command within seconds, whatever runs
            return _main(argv)
    finally:
        warnings.showwarning = shown
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


_command_name = ["exposim"]  # what the watchdog's message names


def _main(argv: list[str] | None) -> int:
    command = _command_name[0] = "exposim"
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        command = f"exposim {args.command}" if getattr(args, "command", None) else "exposim"
        _command_name[0] = command
        for cmd in parser.commands:
            if cmd.error is not None and cmd.name != args.command:
                print(f"exposim: warning: command '{cmd.name}' is broken ({cmd.error})", file=sys.stderr)
        if not getattr(args, "func", None):
            parser.print_help()
            return 2
        try:
            for extra in getattr(args, "extras", ()):  # before any output exists: one line naming the extra
                require(extra)
            result = args.func(args)
            sys.stdout.flush()
        except BrokenPipeError:
            raise
        except ModuleNotFoundError as exc:
            message = missing_extra_message(exc)
            if message is None:
                raise
            print(f"{command}: error: {message}", file=sys.stderr)
            return 1
        except ExposimError as exc:
            print(f"{command}: error: {exc}", file=sys.stderr)
            return 1
        except OSError as exc:
            print(f"{command}: error: {_os_error(exc)}", file=sys.stderr)
            return 1
        return int(result or 0)
    except BrokenPipeError:
        _quiet_stdout()
        return 1
    except KeyboardInterrupt as exc:
        if isinstance(exc, Terminated):
            print(f"{command}: terminated (SIGTERM)", file=sys.stderr)
            return 143
        print(f"{command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
