"""Thread pools: one BLAS/OpenMP thread around arithmetic whose result must not depend on the
machine (:func:`single_thread_pools`), and the shared two-thread pool of the LUT gathers (:func:`lut_pool`).

A multi-threaded BLAS splits a reduction over its threads and sums the parts in another
order: ``np.dot`` of two 2.3-million-element vectors (Zhang's derivative on a BorealHDR
frame) differs in the last bit between 1 and 2 OpenBLAS threads, and Kim's GP-MI amplifies
such bits into different exposures (35.0 vs 1.204 ms at cycle 1 of the shared sample).
:func:`single_thread_pools` is the one place that limits the pools; the closed loops, Kim,
the dataset units and the calibration solver use it.
"""

from __future__ import annotations

import importlib
import threading

__all__ = ["single_thread_pools", "lut_pool"]

_lock = threading.Lock()
_controllers: dict = {}
_LUT_POOL = None


def lut_pool():
    """The two threads that split a large image's lookup-table gather in halves (emulation, noise tables)."""
    global _LUT_POOL
    with _lock:
        if _LUT_POOL is None:
            from concurrent.futures import ThreadPoolExecutor

            _LUT_POOL = ThreadPoolExecutor(max_workers=2, thread_name_prefix="exposim-lut")
        return _LUT_POOL


def single_thread_pools(load: tuple[str, ...] = (), user_api: str | None = None):
    """A context manager limiting thread pools to one thread (threadpoolctl).

    ``load``: modules imported first, so that the pools they bring (SciPy's OpenBLAS,
    scikit-learn's OpenMP) are covered: a limit covers only the libraries loaded when its
    controller is built, and one controller is built per ``load`` (it lists the libraries
    once; entering and leaving the limit then costs microseconds).  ``user_api``:
    ``"blas"`` or ``"openmp"`` to limit only those pools (None: all).
    """
    from threadpoolctl import ThreadpoolController

    key = tuple(load)
    with _lock:
        controller = _controllers.get(key)
        if controller is None:
            for name in key:
                importlib.import_module(name)
            controller = _controllers[key] = ThreadpoolController()
    return controller.limit(limits=1, user_api=user_api)
