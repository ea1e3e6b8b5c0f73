"""NumPy's CPU dispatch in the method workers: AVX-512 off where its sort is slow (AMD Zen 4).

NumPy sorts float64 with x86-simd-sort.  Its AVX-512 kernels store with ``vpcompress`` to
memory, which AMD's Zen 4 (CPU family 25) runs in microcode: on this project's EPYC
development machine ``np.sort`` of Zhang's 2.3 million derivatives takes 133 ms with AVX-512
and 23 ms with the AVX2 kernels of the same NumPy (numpy/x86-simd-sort issue 6).  So on such a
CPU the fork server that starts the method workers is started with NumPy's own switch
``NPY_DISABLE_CPU_FEATURES`` naming its AVX-512 targets; every worker is forked from it, so every
method runs with the same kernels whatever ``--jobs`` is.  The run's own process keeps its
kernels (NumPy reads the switch once, at import).

A sort gives the same values whichever kernel sorts, and the other methods' tables were the
same bytes with and without the switch (tests/emulator/test_numpy_dispatch.py states the check).  Other
kernels change with it too (a vectorised sum may round differently), and Kim's closed loop can
amplify that: over the live study's 48 walks, Kim's emulated runs differed in 2 between code with
and without the switch, and one of them, run again, gives either result by the switch alone
(docs/results/live.md, 2026-11-28 night).  The switch reaches the workers only; methods built in
the caller's process (the live study's live loops) keep its kernels.  A user who sets
``NPY_DISABLE_CPU_FEATURES`` (or ``NPY_ENABLE_CPU_FEATURES``) keeps their setting.
"""

from __future__ import annotations

import contextlib
import functools
import os
from pathlib import Path

__all__ = ["worker_numpy_env", "forkserver_env", "describe", "avx512_sort_is_slow", "avx512_sort_slow_in_this_process"]

#: CPU family of AMD's Zen 3 and Zen 4 (only Zen 4 has AVX-512); Zen 5 (family 26) fixed the store.
_SLOW_FAMILY = 25
_USER_KEYS = ("NPY_DISABLE_CPU_FEATURES", "NPY_ENABLE_CPU_FEATURES")


def _cpu(cpuinfo: str | None) -> tuple[str, int | None, set[str]]:
    """(vendor, family, flags) of the first processor in /proc/cpuinfo's text ('' when unknown)."""
    if cpuinfo is None:
        try:  # the machine's description, not data: the one file this base module reads
            cpuinfo = Path("/proc/cpuinfo").read_text(encoding="ascii", errors="replace")
        except OSError:  # not Linux
            return "", None, set()
    vendor, family, flags = "", None, set()
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        key = key.strip()
        if key == "vendor_id" and not vendor:
            vendor = value.strip()
        elif key == "cpu family" and family is None:
            with contextlib.suppress(ValueError):
                family = int(value.strip())
        elif key == "flags" and not flags:
            flags = set(value.split())
        if not line.strip() and vendor:  # the first processor's block has ended
            break
    return vendor, family, flags


def _multiarray():
    """NumPy's C module, which lists its CPU features and dispatch targets."""
    try:
        from numpy._core import _multiarray_umath
    except ImportError:  # NumPy < 2
        from numpy.core import _multiarray_umath
    return _multiarray_umath


def _avx512_targets() -> list[str]:
    """This NumPy's dispatch targets that use AVX-512 (names differ between NumPy versions)."""
    return [f for f in _multiarray().__cpu_dispatch__ if f == "X86_V4" or f.startswith("AVX512")]


def avx512_sort_is_slow(cpuinfo: str | None = None) -> bool:
    """True on an AMD CPU of family 25 with AVX-512 (Zen 4), where NumPy's AVX-512 sort is slow."""
    vendor, family, flags = _cpu(cpuinfo)
    return vendor == "AuthenticAMD" and family == _SLOW_FAMILY and "avx512f" in flags


@functools.lru_cache(maxsize=1)
def avx512_sort_slow_in_this_process() -> bool:
    """NumPy sorts with AVX-512 in this process, on a CPU where that sort is slow: true in the run's own
    process on Zen 4, false in the method workers (started with those kernels off) and elsewhere."""
    return bool(_multiarray().__cpu_features__.get("AVX512_SKX")) and avx512_sort_is_slow()


def worker_numpy_env(environ=None, cpuinfo: str | None = None) -> dict[str, str]:
    """The variables the workers' fork server starts with ({} where nothing needs changing)."""
    environ = os.environ if environ is None else environ
    if any(k in environ for k in _USER_KEYS) or not avx512_sort_is_slow(cpuinfo):
        return {}
    targets = _avx512_targets()
    return {"NPY_DISABLE_CPU_FEATURES": " ".join(targets)} if targets else {}


@functools.lru_cache(maxsize=1)
def _env_here() -> tuple[tuple[str, str], ...]:
    return tuple(sorted(worker_numpy_env().items()))


def describe() -> str:
    """For run.json: which NumPy kernels the method workers use."""
    env = dict(_env_here())
    if not env:
        return "NumPy's default kernels"
    return (f"NumPy with NPY_DISABLE_CPU_FEATURES={env['NPY_DISABLE_CPU_FEATURES']!r} "
            "(AMD Zen 4: its AVX-512 sort is ~6x slower than the AVX2 one)")


@contextlib.contextmanager
def forkserver_env():
    """Around the start of a worker: the fork server, if this start launches it, gets the variables.

    Only the fork server's start reads them; they are put back at once (the caller holds the
    workers' start lock).
    """
    env = dict(_env_here())
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
