"""One quiet flag and one progress-bar policy for every ``exposim`` sub-command.

``-q/--quiet`` turns progress bars off (``--no-progress`` is kept as a hidden alias of
it).  Bars are drawn on stderr, and only when stderr is a terminal: in a Slurm or CI log
(stderr redirected to a file or a pipe) there is no bar at all.  A command makes its bar
after its arguments have been checked, so an argument error never follows a bar.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["add_quiet", "add_json", "print_json", "bars_enabled", "progress_bar"]


def add_quiet(parser: argparse.ArgumentParser, help: str = "no progress bar") -> None:
    """Add ``-q/--quiet`` (dest ``quiet``) and the hidden alias ``--no-progress``."""
    parser.add_argument("-q", "--quiet", action="store_true", help=help)
    parser.add_argument("--no-progress", dest="quiet", action="store_true", help=argparse.SUPPRESS)


def add_json(parser: argparse.ArgumentParser, help: str = "print results.json to stdout instead of the summary") -> None:
    """Add ``--json`` (dest ``json``)."""
    parser.add_argument("--json", action="store_true", help=help)


def print_json(results) -> None:
    """Print ``results`` as JSON on stdout (paths and numpy values made plain)."""
    import json

    from emulator.io.files import to_jsonable

    print(json.dumps(to_jsonable(results), indent=1))


def bars_enabled(quiet: bool = False, stream=None) -> bool:
    """True when a bar should be drawn: not quiet and ``stream`` (default stderr) is a terminal."""
    stream = sys.stderr if stream is None else stream
    try:
        return not quiet and bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


def progress_bar(quiet: bool = False, **kwargs):
    """A :class:`tqdm.tqdm` on stderr, disabled unless :func:`bars_enabled`."""
    from tqdm import tqdm

    kwargs.setdefault("file", sys.stderr)
    kwargs.setdefault("dynamic_ncols", True)
    return tqdm(disable=not bars_enabled(quiet, kwargs["file"]), **kwargs)
