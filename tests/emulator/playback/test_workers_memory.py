"""Method workers keep the memory a call frees for the next call (glibc): a call that allocates
the same large blocks again does not fault every page in anew.  Counted in page faults (the
process's own counter), never in time."""

from __future__ import annotations

import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc on Linux")

PROBE = '''
import resource, sys
from emulator.playback import worker_child as w
if sys.argv[1] == "worker":
    w._keep_freed_memory()
def faults_of_a_call():  # what a Zhang call does: three 18 MiB arrays at once (derivatives, sort), all freed
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    blocks = [bytearray(18 << 20) for _ in range(3)]  # zero-filled: every page touched
    del blocks
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
faults_of_a_call()
print(min(faults_of_a_call() for _ in range(3)))
'''


def _faults(kind: str) -> int:
    out = subprocess.run([sys.executable, "-c", PROBE, kind], capture_output=True, text=True, check=True)
    return int(out.stdout.strip())


def test_a_worker_reuses_freed_blocks_instead_of_faulting_them_in_again():
    pages = 3 * (18 << 20) // 4096  # 13,824 pages of 4 KiB
    plain = _faults("plain")
    assert plain >= pages // 2  # glibc's default: the freed block went back to the system
    assert _faults("worker") < pages // 20  # kept: reused without faults


RUN_THEN_PROBE = '''
import resource, sys
sys.path.insert(0, sys.argv[3])
from pathlib import Path
from tests.emulator.playback.test_playback import write_static_sequence
from emulator.playback import run
root, _ = write_static_sequence(Path(sys.argv[2]) / "seq", n_cycles=2, shape=(32, 48))
run(root, "classical-50,shim", workers=sys.argv[1])  # the user's own process runs a benchmark, then goes on
def faults_of_a_call():
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    blocks = [bytearray(18 << 20) for _ in range(3)]
    del blocks
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
faults_of_a_call()
print(min(faults_of_a_call() for _ in range(3)))
'''


@pytest.mark.parametrize("workers", ["inline", "process"])
def test_a_run_leaves_its_own_process_malloc_as_it_was(tmp_path, workers):
    """Only the method workers keep freed memory: the process that runs the benchmark (a user's own script
    with ``workers="inline"`` too) still hands freed blocks back to the system."""
    from pathlib import Path

    tests = str(Path(__file__).parent)
    out = subprocess.run([sys.executable, "-c", RUN_THEN_PROBE, workers, str(tmp_path), tests],
                         capture_output=True, text=True, check=True)
    assert int(out.stdout.strip().splitlines()[-1]) >= 3 * (18 << 20) // 4096 // 2


def test_keeping_freed_memory_needs_glibc_and_ctypes(monkeypatch):
    """Elsewhere (another C library, a Python without ctypes) a worker starts as it would without it."""
    import ctypes

    from emulator.playback import worker_child as w

    calls = []

    class Libc:
        def __init__(self, name):
            calls.append(name)
            self.mallopt = lambda *a: calls.append(a) or 1

    monkeypatch.setattr(ctypes, "CDLL", Libc)
    monkeypatch.setattr(w, "_glibc", lambda: False)  # e.g. musl, whose mallopt numbers its parameters otherwise
    w._keep_freed_memory()
    assert calls == []
    monkeypatch.setattr(w, "_glibc", lambda: True)
    monkeypatch.setitem(sys.modules, "ctypes", None)  # a Python built without ctypes
    w._keep_freed_memory()
    assert calls == []
    monkeypatch.delitem(sys.modules, "ctypes")
    monkeypatch.setitem(sys.modules, "ctypes", ctypes)
    w._keep_freed_memory()
    assert calls == ["libc.so.6", (w._M_MMAP_THRESHOLD, w.HEAP_BLOCK_BYTES), (w._M_TRIM_THRESHOLD, w.KEEP_FREED_BYTES)]
    import platform

    assert w._glibc() == (platform.libc_ver()[0] == "glibc")  # this machine's C library
