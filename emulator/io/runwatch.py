"""The watcher of a run folder: what a run's process leaves when it dies is finished by another
(:func:`watch_run`).

A process killed by a signal (SIGKILL, SIGBUS, SIGSEGV) runs no Python code on its way out, so it
cannot set its own ``run.json`` from ``running`` to ``failed``, remove its ``run.lock`` or unlink
its shared-memory image blocks.  :func:`watch_run` starts a small process (a fresh interpreter
of its own session, importing only the standard library) that waits on a pipe from the run.  The
run writes ``done`` into it when it ends in any orderly way (complete, failed, interrupted: it
has then written ``run.json`` itself).  When the pipe closes without ``done``, the run's process
is gone: the watcher sets ``run.json`` to ``failed`` with an ``error`` saying so (only while the
file still says ``running`` and names the dead process as its writer), removes ``run.lock`` if
that process held it, and unlinks the process's ``/dev/shm/exposim-<pid>-*`` blocks.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
from pathlib import Path

__all__ = ["watch_run", "RunWatch", "finish_dead_run"]

_DONE = b"done\n"


class RunWatch:
    """The run's end of the watcher's pipe; :meth:`done` (or the context manager) tells it the run ended."""

    def __init__(self, proc: subprocess.Popen | None) -> None:
        self._proc = proc

    def done(self) -> None:
        """Tell the watcher the run ended in order (it then exits without touching anything)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        with contextlib.suppress(OSError, ValueError):
            proc.stdin.write(_DONE)
            proc.stdin.close()
        with contextlib.suppress(subprocess.TimeoutExpired, OSError):
            proc.wait(5)

    def __enter__(self) -> "RunWatch":
        return self

    def __exit__(self, *exc) -> None:
        self.done()


def watch_run(run_dir: str | os.PathLike) -> RunWatch:
    """Start the watcher of the run this process writes into ``run_dir`` (see the module docstring);
    where no process can be started, the run goes on unwatched."""
    try:  # this file as a script: the standard library only, no package import
        proc = subprocess.Popen([sys.executable, "-I", os.path.abspath(__file__), str(os.getpid()),
                                 os.path.abspath(run_dir)],
                                stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True)  # a terminal's Ctrl-C reaches the run only
    except OSError:
        return RunWatch(None)
    return RunWatch(proc)


def _main(pid: int, run_dir: str) -> None:
    data = b""
    with contextlib.suppress(OSError):
        while True:
            chunk = os.read(0, 64)
            if not chunk:
                break
            data += chunk
    if _DONE not in data:
        finish_dead_run(pid, Path(run_dir))


def finish_dead_run(pid: int, run_dir: Path, *, shm_dir: str = "/dev/shm") -> bool:
    """Finish what the dead process ``pid`` left of its run in ``run_dir``; True if ``run.json`` was set."""
    for entry in _listdir(shm_dir):
        if entry.startswith(f"exposim-{int(pid)}-"):
            with contextlib.suppress(OSError):
                os.unlink(os.path.join(shm_dir, entry))
    set_failed = False
    path = run_dir / "run.json"
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        info = None
    if isinstance(info, dict) and info.get("status") == "running" \
            and (info.get("writer") or {}).get("pid") == int(pid):
        info["status"] = "failed"
        info["error"] = (f"the run's process (pid {pid}) ended without finishing: killed by a signal (SIGKILL, "
                         "SIGBUS, SIGSEGV) or crashed; its tables hold the cycles it wrote, --resume continues it")
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        with contextlib.suppress(OSError):
            tmp.write_text(json.dumps(info, indent=2, allow_nan=False) + "\n", encoding="utf-8")
            os.replace(tmp, path)
            set_failed = True
    lock = run_dir / "run.lock"
    with contextlib.suppress(OSError, ValueError):
        if json.loads(lock.read_text(encoding="utf-8")).get("pid") == int(pid):
            lock.unlink()
    return set_failed


def _listdir(folder: str) -> list[str]:
    try:
        return os.listdir(folder)
    except OSError:
        return []


if __name__ == "__main__":
    _main(int(sys.argv[1]), sys.argv[2])
