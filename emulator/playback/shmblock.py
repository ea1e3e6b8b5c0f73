"""Shared-memory image blocks of the method workers, reserved when made (:func:`reserve_block`).

A POSIX shared-memory object is a file in ``/dev/shm`` (a tmpfs) whose pages are taken when they
are first written.  Made with ``ftruncate`` alone, as :class:`multiprocessing.shared_memory.SharedMemory`
makes it, a block larger than the room left there is created without complaint and the first
write through its mapping past that room raises SIGBUS, which kills the run's process (Docker's
default ``/dev/shm`` is 64 MiB; eight methods at 1920x1200 need 73.7 MB).  :func:`reserve_block`
takes every page when the block is made (``posix_fallocate``), so a full ``/dev/shm`` is an
``OSError`` there, before any image is written: the worker then gets its images through its pipe
(:mod:`emulator.playback.workers`), the run says so in one line (:func:`shortage_note`), and the
results are the same bytes.

Blocks are named ``exposim-<run pid>-<token>``, so that what a run that died leaves behind can be
found and removed by the run's watcher (:mod:`emulator.io.runwatch`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
from multiprocessing import shared_memory

__all__ = ["reserve_block", "block_prefix", "shortage_note", "SHM_DIR", "SharedMemoryWarning"]

#: Where POSIX shared memory lives on Linux (what a shortage names).
SHM_DIR = "/dev/shm"


class SharedMemoryWarning(UserWarning):
    """``/dev/shm`` had no room for a method's image block: its images go through its pipe."""


def block_prefix(pid: int | None = None) -> str:
    """The name prefix of the blocks the process ``pid`` (default: this one) makes."""
    return f"exposim-{os.getpid() if pid is None else int(pid)}-"


def reserve_block(size: int) -> shared_memory.SharedMemory | None:
    """A new shared-memory block of ``size`` bytes with every page taken, or None where the system
    has no room for it (``/dev/shm`` full or too small); never a block whose first write can fail."""
    size = max(int(size), 1)
    try:
        shm = shared_memory.SharedMemory(name=block_prefix() + secrets.token_hex(6), create=True, size=size)
    except OSError as exc:
        if exc.errno in (errno.ENOSPC, errno.ENOMEM, errno.EFBIG):
            return None
        raise
    fd = getattr(shm, "_fd", -1)
    if fd >= 0 and hasattr(os, "posix_fallocate"):
        try:
            os.posix_fallocate(fd, 0, size)
        except OSError as exc:
            with contextlib.suppress(OSError, BufferError):
                shm.close()
                shm.unlink()
            if exc.errno in (errno.ENOSPC, errno.ENOMEM, errno.EFBIG):
                return None
            if exc.errno not in (errno.EINVAL, errno.EOPNOTSUPP):  # a file system without fallocate: as before
                raise
            return shared_memory.SharedMemory(name=block_prefix() + secrets.token_hex(6), create=True, size=size)
    return shm


def _free_bytes() -> int | None:
    try:
        st = os.statvfs(SHM_DIR)
    except OSError:
        return None
    return st.f_bavail * st.f_frsize


def shortage_note(sizes: dict[str, int], total: int) -> str | None:
    """One line saying which of ``total`` methods got their images through pipes because ``/dev/shm``
    had no room (``sizes``: method -> block bytes it needed), with the room needed; None if none."""
    if not sizes:
        return None
    need = sum(sizes.values())
    free = _free_bytes()
    each = max(sizes.values())
    return (f"{SHM_DIR} had no room for the image blocks of {len(sizes)} of {total} methods ({', '.join(sizes)}; "
            f"{each / 1e6:.1f} MB each, {need / 1e6:.1f} MB more needed"
            + (f", {free / 1e6:.1f} MB free" if free is not None else "")
            + "): their images went through pipes (slower, the same results); enlarge it (docker run --shm-size=256m)")
