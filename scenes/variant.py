"""Choosing a Mitsuba variant safely.

``cuda_ad_rgb`` (an NVIDIA GPU) is the fastest, then ``llvm_ad_rgb``, then ``scalar_rgb``; but
Dr.Jit aborts the whole process (no exception) when the system's LLVM is too old or missing.  So a JIT
variant is only ever set in this process after a child Python process has
loaded it and rendered a tiny scene with it.  Results are cached per process.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading

from scenes.errors import RenderError

__all__ = ["VALID_VARIANTS", "PREFERRED_VARIANTS", "ENV_VARIANT", "choose_variant", "probe_variant",
           "ensure_variant", "check_variant_name", "gpu_description"]

#: RGB variants the scenes can render with (radiance is RGB).
VALID_VARIANTS = ("llvm_ad_rgb", "scalar_rgb", "cuda_ad_rgb")
#: Tried in order by :func:`choose_variant` (``cuda_ad_rgb`` only where an NVIDIA driver is present).
PREFERRED_VARIANTS = ("cuda_ad_rgb", "llvm_ad_rgb", "scalar_rgb")
#: Environment variable that forces a variant (still probed if it is a JIT variant).
ENV_VARIANT = "EXPOSIM_MITSUBA_VARIANT"

#: Run in a child process as ``python -c _PROBE_SCRIPT VARIANT``; success prints the marker.
_PROBE_SCRIPT = """
import sys
import numpy as np
import mitsuba as mi
mi.set_variant(sys.argv[1])
scene = mi.load_dict({
    "type": "scene",
    "integrator": {"type": "path", "max_depth": 2},
    "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 3}},
    "ball": {"type": "sphere", "center": [0, 0, 3]},
    "sky": {"type": "constant"},
})
img = np.array(mi.render(scene, spp=2, seed=0))
assert img.shape == (3, 4, 3) and np.isfinite(img).all()
print("exposim-variant-probe-ok")
"""
_MARKER = "exposim-variant-probe-ok"

_lock = threading.Lock()
_probed: dict[str, bool] = {}
_chosen: str | None = None


def _is_jit(variant: str) -> bool:
    return variant.startswith(("llvm_", "cuda_"))


def probe_variant(variant: str, *, timeout_s: float = 180.0) -> bool:
    """True when ``variant`` loads and renders in a child process.

    The child may crash in any way (abort, segfault, exception, timeout); this
    process only sees a False.  Not cached: see :func:`ensure_variant`.
    """
    try:
        proc = subprocess.run([sys.executable, "-c", _PROBE_SCRIPT, variant], capture_output=True, text=True,
                              timeout=timeout_s, check=False, stdin=subprocess.DEVNULL)
    except (subprocess.TimeoutExpired, OSError):
        return False
    return proc.returncode == 0 and _MARKER in proc.stdout


def _has_nvidia_driver() -> bool:
    """True where an NVIDIA driver is installed (its device node or ``nvidia-smi``): only then is the CUDA
    variant worth a probe."""
    return os.path.exists("/dev/nvidiactl") or shutil.which("nvidia-smi") is not None


def gpu_description() -> str | None:
    """The NVIDIA GPU and its driver as ``nvidia-smi`` names them (``"NVIDIA H200, 580.159.04"``), for the
    records of measurements that ran on it; None where it cannot say."""
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=name,driver_version", "--format=csv,noheader"],
                             capture_output=True, text=True, timeout=30).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        return None
    return out or None


def _usable(variant: str) -> bool:
    with _lock:
        if variant not in _probed:
            _probed[variant] = probe_variant(variant) if _is_jit(variant) else True
        return _probed[variant]


def check_variant_name(variant: str) -> str:
    """Return ``variant`` if it is one of :data:`VALID_VARIANTS` (no probe).

    Raises
    ------
    RenderError
        Unknown variant name (the message lists the valid ones).
    """
    if variant not in VALID_VARIANTS:
        raise RenderError(f"unknown Mitsuba variant {variant!r}; valid: {', '.join(VALID_VARIANTS)}")
    return variant


def ensure_variant(variant: str) -> str:
    """Check that ``variant`` is valid and (for JIT variants) probed OK; return it.

    Call this before loading the variant in this process.

    Raises
    ------
    RenderError
        Unknown variant name (the message lists the valid ones), or a JIT
        variant whose probe failed.
    """
    check_variant_name(variant)
    if not _usable(variant):
        raise RenderError(f"Mitsuba variant {variant!r} does not work on this machine (the probe in a child "
                          f"process failed: old or missing LLVM/CUDA?); use scalar_rgb")
    return variant


def choose_variant(*, refresh: bool = False) -> str:
    """The Mitsuba variant renders use: ``cuda_ad_rgb`` where an NVIDIA GPU renders with it, else
    ``llvm_ad_rgb`` when it works, else ``scalar_rgb``.

    The environment variable ``EXPOSIM_MITSUBA_VARIANT`` forces a variant without
    a probe here, so reading renders from the cache never starts a child process;
    :func:`scenes.render` still probes a forced JIT variant before it renders
    with it, and refuses it if the probe fails.  The automatic choice is cached
    for the process; ``refresh=True`` probes again.

    Returns
    -------
    str
        A variant name from :data:`VALID_VARIANTS`.
    """
    global _chosen
    if refresh:
        with _lock:
            _probed.clear()
            _chosen = None
    forced = os.environ.get(ENV_VARIANT, "").strip()
    if forced:
        return check_variant_name(forced)
    if _chosen is None:
        for v in PREFERRED_VARIANTS:
            if v.startswith("cuda_") and not _has_nvidia_driver():
                continue
            if _usable(v):
                _chosen = v
                break
        else:  # pragma: no cover - scalar_rgb is always considered usable
            raise RenderError("no usable Mitsuba variant")
    return _chosen
