"""One quiet flag and one progress-bar policy for every ``exposim`` sub-command.

``-q/--quiet`` turns progress bars off (``--no-progress`` is kept as a hidden alias of
it).  Bars are drawn on stderr, and only when stderr is a terminal: in a Slurm or CI log
(stderr redirected to a file or a pipe) there is no bar; a long command prints plain stage
lines there instead (:func:`log_lines`): one as each stage (method) starts, one at least every
:data:`LOG_EVERY_S` seconds within it, one as it ends.  A command makes its bar
after its arguments have been checked, so an argument error never follows a bar.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import threading

from emulator.io.files import to_jsonable

__all__ = ["add_quiet", "add_json", "print_json", "bars_enabled", "progress_bar", "log_lines", "progress_arg",
           "LOG_EVERY_S"]

#: Most seconds between two progress lines in a log (stderr not a terminal).
LOG_EVERY_S = 20.0


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



def log_lines(command: str, quiet: bool = False, stream=None, clock=None, heartbeat: bool = False):
    """Where stderr is not a terminal (a log: nohup, CI, Slurm) and not ``quiet``: the callback
    ``progress(stage, done, total)`` that prints ``COMMAND [12 s]: STAGE done/total`` on stderr as a stage
    starts (``done == 0`` or a new stage), when a report comes :data:`LOG_EVERY_S` seconds or more after
    the last line, and as it ends (``done == total``).  None on a terminal (the bars serve there) or when
    quiet.

    ``heartbeat``: a daemon thread also prints ``STAGE done/total, working`` when :data:`LOG_EVERY_S`
    seconds pass without a line (one slow image), until the callback's ``close()``; use it as a context
    manager.  ``clock`` (default :func:`time.monotonic`) gives seconds; a test passes its own.
    """
    import time

    stream = sys.stderr if stream is None else stream
    if quiet or bars_enabled(False, stream):
        return None
    return _LogLines(command, stream, time.monotonic if clock is None else clock, heartbeat)


class _LogLines:
    """The callback of :func:`log_lines`."""

    def __init__(self, command: str, stream, clock, heartbeat: bool) -> None:
        self.command, self.stream, self.clock = command, stream, clock
        self.start = clock()
        # before the first report the command is "preparing": the heartbeat's first line comes after LOG_EVERY_S
        self.stage, self.done, self.total, self.last = "preparing", 0, None, self.start
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = None
        if heartbeat:
            self._thread = threading.Thread(target=self._beat, daemon=True, name="exposim-log-lines")
            self._thread.start()

    def _line(self, now: float, suffix: str = "") -> None:
        count = ("" if not self.done else f" {self.done}") if self.total is None else f" {self.done}/{self.total}"
        print(f"{self.command} [{now - self.start:.0f} s]: {self.stage}{count}{suffix}", file=self.stream, flush=True)
        self.last = now

    def __call__(self, stage: str, done: int, total) -> None:
        with self._lock:
            now = self.clock()
            new = stage != self.stage
            self.stage, self.done, self.total = stage, done, total
            if new or done == 0 or done == total or now - self.last >= LOG_EVERY_S:
                self._line(now)

    def _beat(self) -> None:
        while not self._stop.wait(1.0):
            self.beat()

    def beat(self) -> None:
        """One heartbeat: a line when :data:`LOG_EVERY_S` seconds passed since the last one."""
        with self._lock:
            if self._stop.is_set():  # closed: the command has ended, nothing more is said
                return
            now = self.clock()
            if now - self.last >= LOG_EVERY_S:
                self._line(now, ", working")

    def close(self) -> None:
        """Stop the heartbeat (if any): no line is printed once this returns."""
        with self._lock:
            self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@contextlib.contextmanager
def progress_arg(command: str, quiet: bool = False):
    """What a library's ``progress`` argument gets, as a context: True (bars) on a terminal, :func:`log_lines`
    (with its heartbeat, stopped on leaving) in a log, False when quiet."""
    if bars_enabled(quiet):
        yield True
        return
    lines = log_lines(command, quiet, heartbeat=True)
    if lines is None:
        yield False
        return
    with lines:
        yield lines
