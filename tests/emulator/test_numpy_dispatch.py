"""NumPy's kernels in the method workers (emulator.numpy_dispatch): AVX-512 off on AMD Zen 4 only."""

from __future__ import annotations

import multiprocessing
import os

import numpy as np
import pytest

from emulator import numpy_dispatch as nd
from emulator.autoexposure import zhang
from emulator.playback import RunConfig
from emulator.playback.workers import start_methods, stop_methods

ZEN4 = "processor\t: 0\nvendor_id\t: AuthenticAMD\ncpu family\t: 25\nmodel\t\t: 17\nflags\t\t: fpu sse avx2 avx512f avx512dq\n\n"
ZEN3 = ZEN4.replace(" avx512f avx512dq", "")
ZEN5 = ZEN4.replace("cpu family\t: 25", "cpu family\t: 26")
INTEL = ZEN4.replace("AuthenticAMD", "GenuineIntel").replace(": 25", ": 6")


@pytest.mark.parametrize(("text", "slow"), [(ZEN4, True), (ZEN3, False), (ZEN5, False), (INTEL, False),
                                            ("", False), ("garbage without colons\n", False),
                                            ("vendor_id: AuthenticAMD\ncpu family: x\nflags: avx512f\n", False)])
def test_only_amd_zen4_with_avx512_counts_as_slow(text, slow):
    assert nd.avx512_sort_is_slow(text) is slow


def test_only_the_first_processor_is_read():
    second = ZEN4.replace("processor\t: 0", "processor\t: 1")
    assert nd.avx512_sort_is_slow(INTEL + second) is False
    assert nd.avx512_sort_is_slow(ZEN4 + INTEL.replace("processor\t: 0", "processor\t: 1")) is True


def test_on_zen4_the_workers_get_this_numpys_avx512_targets_and_a_users_setting_wins():
    env = nd.worker_numpy_env(environ={}, cpuinfo=ZEN4)
    targets = nd._avx512_targets()
    assert env == ({"NPY_DISABLE_CPU_FEATURES": " ".join(targets)} if targets else {})
    assert all(t == "X86_V4" or t.startswith("AVX512") for t in targets)
    assert nd.worker_numpy_env(environ={"NPY_DISABLE_CPU_FEATURES": "AVX2"}, cpuinfo=ZEN4) == {}
    assert nd.worker_numpy_env(environ={"NPY_ENABLE_CPU_FEATURES": "X86_V3"}, cpuinfo=ZEN4) == {}
    assert nd.worker_numpy_env(environ={}, cpuinfo=INTEL) == {}


def test_the_fork_server_variables_are_put_back(monkeypatch):
    monkeypatch.setattr(nd, "_env_here", lambda: (("NPY_DISABLE_CPU_FEATURES", "X86_V4"),))
    monkeypatch.delenv("NPY_DISABLE_CPU_FEATURES", raising=False)
    with nd.forkserver_env():
        assert os.environ["NPY_DISABLE_CPU_FEATURES"] == "X86_V4"
    assert "NPY_DISABLE_CPU_FEATURES" not in os.environ
    monkeypatch.setenv("NPY_DISABLE_CPU_FEATURES", "mine")
    with pytest.raises(RuntimeError), nd.forkserver_env():
        raise RuntimeError
    assert os.environ["NPY_DISABLE_CPU_FEATURES"] == "mine"


def _features(queue):
    from numpy._core._multiarray_umath import __cpu_features__

    queue.put(bool(__cpu_features__.get("AVX512_SKX")))


def test_the_method_workers_fork_server_runs_without_avx512_where_its_sort_is_slow():
    """A real method worker starts the fork server (if none runs); a process forked from that
    server reports the kernels every worker has."""
    workers = start_methods("classical-50", RunConfig(), None)
    try:
        ctx = multiprocessing.get_context("forkserver")
        queue = ctx.Queue()
        proc = ctx.Process(target=_features, args=(queue,))
        proc.start()
        in_worker = queue.get(timeout=60)
        proc.join(10)
    finally:
        stop_methods(workers)
    from numpy._core._multiarray_umath import __cpu_features__

    here = bool(__cpu_features__.get("AVX512_SKX"))
    expect = here and not nd.worker_numpy_env()
    assert in_worker is expect
    assert "NPY_DISABLE_CPU_FEATURES" not in os.environ or nd.worker_numpy_env() == {}


@pytest.mark.parametrize("slow", [True, False])
def test_zhangs_sort_is_numpys_sort_on_either_path(monkeypatch, slow):
    monkeypatch.setattr(zhang, "_avx512_sort_slow_here", lambda: slow)
    d = np.random.default_rng(3).standard_normal(1 << 17) * 10.0 ** np.random.default_rng(4).integers(-300, 300, 1 << 17)
    d[:5] = [np.inf, -np.inf, np.nan, 0.0, -0.0]
    out = zhang.sorted_values(d)
    ref = np.sort(d)
    assert np.array_equal(out, ref, equal_nan=True)


@pytest.mark.parametrize("mode", ["borealhdr", "paper"])
def test_every_methods_table_is_the_same_bytes_with_and_without_numpys_avx512_kernels(sample_seq, tmp_path, mode):
    """The switch the workers get changes no result: each run here has one kernel set in every
    process (inline methods; the switch in the environment of the whole run, or no switch)."""
    import subprocess
    import sys

    targets = " ".join(nd._avx512_targets())
    tables = {}
    for name, extra in (("default", {}), ("avx2", {"NPY_DISABLE_CPU_FEATURES": targets} if targets else {})):
        env = {k: v for k, v in os.environ.items() if k not in ("NPY_DISABLE_CPU_FEATURES", "NPY_ENABLE_CPU_FEATURES")}
        env.update(extra)
        out = tmp_path / name
        subprocess.run([sys.executable, "-m", "emulator.commands.cli", "run", str(sample_seq), "--methods", "all", "--mode", mode,
                        "--workers", "inline", "-o", str(out), "--no-progress", "-q"], env=env, check=True,
                       capture_output=True)
        tables[name] = {p.parent.name: p.read_bytes() for p in sorted(out.glob("*/exposures.csv"))}
    assert len(tables["default"]) == 7
    assert tables["avx2"] == tables["default"]


_SHIM_DIGEST = """
import hashlib, sys
import numpy as np
from emulator.autoexposure import shim, to_gray
from emulator.autoexposure.base import RGGB_BAYER_CODE
from emulator.io.borealhdr import load_sequence
cycle = load_sequence(sys.argv[1])[1]
h = hashlib.sha256(b"".join(t.tobytes() for t in shim._paper_tables(4095.0, shim.GAMMAS)))
for b in (1.0, 8.0, 32.0):
    h.update(shim.gamma_metrics_paper(to_gray(cycle.frames["left"][b].load(), RGGB_BAYER_CODE))[0].tobytes())
print(h.hexdigest())
"""


def test_shims_paper_metric_is_the_same_bits_under_avx2_and_avx512_kernels(sample_seq):
    """Paper-mode Shim's gamma tables and metrics (float64, every bit) do not depend on the kernels
    NumPy picks, so a method worker without AVX-512 and the run's own process agree.  (Before, its
    float32 power and log10 were SVML's under AVX-512 and the C library's otherwise: the metrics
    moved by about 1e-7 relative between the two.)  On a CPU without AVX-512 both runs use AVX2."""
    import subprocess
    import sys

    targets = " ".join(nd._avx512_targets())
    digests = []
    for extra in ({}, {"NPY_DISABLE_CPU_FEATURES": targets} if targets else {}):
        env = {k: v for k, v in os.environ.items() if k not in ("NPY_DISABLE_CPU_FEATURES", "NPY_ENABLE_CPU_FEATURES")}
        env.update(extra)
        proc = subprocess.run([sys.executable, "-c", _SHIM_DIGEST, str(sample_seq)], env=env, check=True,
                              capture_output=True, text=True)
        digests.append(proc.stdout.strip())
    assert len(digests[0]) == 64 and digests[0] == digests[1]
