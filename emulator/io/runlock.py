"""The lock of a run folder, ``run.lock``: :class:`RunLock` (see :mod:`emulator.io.runfolder`)."""

from __future__ import annotations

import contextlib
import datetime as _dt
import errno
import fcntl
import json
import os
import socket
from pathlib import Path

from emulator.errors import RunLockedError

__all__ = ["LOCK_FILE", "RunLock", "utc_now_iso"]

LOCK_FILE = "run.lock"


def utc_now_iso() -> str:
    """Now, UTC, ISO 8601 to the second (the times a run folder records)."""
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")



def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def _describe(owner: dict) -> str:
    return (f"pid {owner.get('pid', '?')} on {owner.get('host', '?')}"
            + (f", since {owner['started']}" if owner.get("started") else ""))


class RunLock:
    """Exclusive lock on a run folder (see the module docstring).

    Use :meth:`acquire`; :meth:`release` (or the context manager) removes ``run.lock``.
    ``stale_owner`` is the owner of a stale lock that was taken over, else None.
    """

    def __init__(self, path: Path, fd: int, owner: dict, stale_owner: dict | None) -> None:
        self.path = path
        self._fd = fd
        self.owner = owner
        self.stale_owner = stale_owner

    @classmethod
    def acquire(cls, run_dir: str | os.PathLike) -> "RunLock":
        """Take the lock of ``run_dir`` or raise :class:`RunLockedError` naming the live holder."""
        run_dir = Path(run_dir)
        path = run_dir / LOCK_FILE
        owner = {"pid": os.getpid(), "host": socket.gethostname(), "started": utc_now_iso()}
        tmp = run_dir / f".{LOCK_FILE}.{os.getpid()}.tmp"
        tmp.write_text(json.dumps(owner) + "\n")
        stale = None
        try:
            for _ in range(5):
                try:
                    os.link(tmp, path)  # atomic: fails if a lock exists; the content is complete
                except FileExistsError:
                    pass
                fd = cls._open(path)
                if fd is None:
                    continue  # removed meanwhile: try again
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except OSError as exc:
                    held = cls._read_owner(fd)
                    os.close(fd)
                    if exc.errno in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                        raise RunLockedError(
                            f"{run_dir}: the run folder is being written by another process ({_describe(held)}); "
                            "wait for it to finish or stop it, then --resume"
                        ) from None
                    raise
                if not cls._same_file(fd, path):  # replaced or removed between open and flock
                    os.close(fd)
                    continue
                held = cls._read_owner(fd)
                if held == owner:
                    return cls(path, fd, owner, stale)
                # A lock file whose flock is free: its writer is gone, unless a live process on
                # this host owns it (it has just created it and not yet locked it).
                same_host = held.get("host") == owner["host"]
                pid = held.get("pid")
                if same_host and isinstance(pid, int) and pid != os.getpid() and _pid_alive(pid):
                    os.close(fd)
                    raise RunLockedError(
                        f"{run_dir}: the run folder is being written by another process ({_describe(held)}); "
                        "wait for it to finish or stop it, then --resume"
                    )
                stale = held
                os.replace(tmp, path)  # take over: our owner record, atomically
                tmp.write_text(json.dumps(owner) + "\n")
                os.close(fd)
            raise RunLockedError(f"{path}: could not take the lock (it keeps changing); try again")
        finally:
            tmp.unlink(missing_ok=True)

    @staticmethod
    def _open(path: Path) -> int | None:
        try:
            return os.open(path, os.O_RDWR)
        except FileNotFoundError:
            return None

    @staticmethod
    def _same_file(fd: int, path: Path) -> bool:
        try:
            a, b = os.fstat(fd), os.stat(path)
        except FileNotFoundError:
            return False
        return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)

    @staticmethod
    def _read_owner(fd: int) -> dict:
        try:
            data = os.pread(fd, 4096, 0)
            owner = json.loads(data.decode() or "{}")
        except (OSError, ValueError):
            return {}
        return owner if isinstance(owner, dict) else {}

    def release(self) -> None:
        """Remove ``run.lock`` (if it is still ours) and drop the lock."""
        if self._fd is None:
            return
        with contextlib.suppress(OSError):
            if self._same_file(self._fd, self.path):
                self.path.unlink()
        os.close(self._fd)
        self._fd = None

    def __enter__(self) -> "RunLock":
        return self

    def __exit__(self, *exc) -> None:
        self.release()
