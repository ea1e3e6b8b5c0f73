"""Imported once by the fork server that starts method workers, so that every worker starts with
what the built-in methods load on their first call (SciPy, scikit-learn, the thread-pool
controller) already loaded and shared, instead of loading it again in each worker of each run."""

from __future__ import annotations

import contextlib

with contextlib.suppress(ImportError):  # an environment without them still runs the other methods
    import scipy.interpolate  # noqa: F401  (Zhang)
    import scipy.linalg.lapack  # noqa: F401  (Kim)
    import scipy.ndimage  # noqa: F401  (Zhang)
    import sklearn.exceptions  # noqa: F401  (Kim)
    import sklearn.gaussian_process  # noqa: F401  (Kim)
    import sklearn.gaussian_process.kernels  # noqa: F401  (Kim)

import emulator.autoexposure.builtin  # noqa: E402,F401
import emulator.playback.worker_child  # noqa: E402,F401
from emulator.pools import single_thread_pools  # noqa: E402

with single_thread_pools(user_api="blas"):  # the controller lists the loaded libraries once, here
    pass
