"""The last resort for Ctrl-C and SIGTERM: a command that has not ended some seconds after the
signal is ended for it (:func:`watchdog`).

Commands stop on a signal in Python code (a run marks itself "interrupted", ``synth`` stops
after the image it renders).  Native code can delay that without bound: a renderer that
installs its own SIGINT handler while it works, or a library call that never returns to the
interpreter.  The watchdog does not depend on the interpreter: Python's C-level handler
writes every signal's number to a pipe (:func:`signal.set_wakeup_fd`) at once, a thread
reading it waits :data:`FORCED_EXIT_AFTER_S` for the command to end, and then removes the
staging folders registered with :func:`remove_at_forced_exit`, says so in one line and exits
with 130 (SIGINT) or 143 (SIGTERM).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import threading
from collections.abc import Callable

__all__ = ["watchdog", "remove_at_forced_exit", "FORCED_EXIT_AFTER_S"]

#: Seconds a command gets after Ctrl-C or SIGTERM to stop by itself.
FORCED_EXIT_AFTER_S = 10.0

_lock = threading.Lock()
_staging: set[str] = set()


def remove_at_forced_exit(path) -> None:
    """Remove the folder ``path`` (a staging folder, never a finished result) if the watchdog ends the process."""
    with _lock:
        _staging.add(os.fspath(path))


def _force(command: str, signum: int, grace_s: float) -> None:
    with _lock:
        paths = list(_staging)
    for path in paths:
        shutil.rmtree(path, ignore_errors=True)
    what = "terminated (SIGTERM)" if signum == signal.SIGTERM else "interrupted"
    with contextlib.suppress(OSError):
        os.write(2, f"\n{command}: {what}; ended {grace_s:g} s after the signal\n".encode())
    os._exit(143 if signum == signal.SIGTERM else 130)


def _watch(fd: int, done: threading.Event, command: Callable[[], str], grace_s: float) -> None:
    try:
        while True:
            try:
                data = os.read(fd, 64)
            except OSError:
                return
            if not data:  # the command ended (the write end is closed)
                return
            sigs = [b for b in data if b in (signal.SIGINT, signal.SIGTERM)]
            if not sigs:
                continue
            if done.wait(grace_s):
                return
            _force(command(), sigs[0], grace_s)
    finally:
        with contextlib.suppress(OSError):
            os.close(fd)


@contextlib.contextmanager
def watchdog(command: Callable[[], str], grace_s: float = FORCED_EXIT_AFTER_S):
    """While the block runs, a SIGINT or SIGTERM not followed by the block's end within ``grace_s``
    ends the process (see the module).  ``command()`` names the command in the message.  Only in
    the main thread, and only where no other wakeup file descriptor is set."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    r, w = os.pipe()
    os.set_blocking(w, False)
    try:
        old = signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    except (ValueError, OSError):  # pragma: no cover - not the main thread of the main interpreter
        os.close(r)
        os.close(w)
        yield
        return
    if old != -1:  # someone else's (an event loop): leave it theirs
        signal.set_wakeup_fd(old)
        os.close(r)
        os.close(w)
        yield
        return
    done = threading.Event()
    thread = threading.Thread(target=_watch, args=(r, done, command, float(grace_s)), daemon=True,
                              name="exposim-signal-watchdog")
    thread.start()
    try:
        yield
    finally:
        done.set()
        signal.set_wakeup_fd(-1)
        os.close(w)  # the reader sees the end and closes its side
