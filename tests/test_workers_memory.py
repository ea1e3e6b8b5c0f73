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
from emulator.playback import _worker_child as w
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
