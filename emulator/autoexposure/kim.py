"""M_Kim: entropy-weighted gradient metric and Bayesian-optimisation control (Kim, Cho, Kim, ICRA 2018).

Spec section 5.  Each frame gives one scalar metric E (an entropy-weighted sum of squared
gradients); a Gaussian process over (exposure, E) pairs of a sliding window of the last
frames is maximised with the GP-MI acquisition; once the chosen point's posterior standard
deviation falls to ``SIGMA_STOP`` the GP mean's argmax on a fine grid is returned.  The
output always lies on the grid [0.5, 35] ms.

borealhdr mode (REF)
    Per-pixel entropy from the *global* 256-bin histogram of Y_8 = floor(Y / 16),
    ``H_i = -p(Y_8i) log2 p(Y_8i)``; gradients ``cv2.Sobel(Y_8, CV_16U)`` (negatives
    saturate to 0) squared and summed in uint16 (wrapping mod 65536); weights
    ``exp(+(H - mu)^2 / (2 sigma^2))`` (REF's sign bug), computed overflow-free as a
    softmax; GP-MI gamma = ln 8.  Every pixel quantity depends on the pixel only through
    its Y_8 bin (except Q), so weights, activation and mask are 256-entry tables (the
    histogram from ``cv2.calcHist``, the weight gathered with ``cv2.LUT``).
paper mode
    Kim's own choices: local 3x3 entropy (``entropyfilt``) on a 1/4-scale image, float
    gradients, the Gaussian weight with the minus sign, GP-MI gamma = 7 (Kim's MATLAB).
    The sliding window (BorealHDR's adaptation for a moving camera) is kept.

Guards (both modes): a non-finite metric (REF on a flat image: sigma_H = 0 or max H = min H;
REF raises ``ValueError: Input y contains NaN``) is not inserted and t is returned; a failed
GP fit removes the newest point and returns t.  In paper mode the metric takes its limits
instead (equal weights; a flat image has no gradient, so E = 0), so a black or white frame
is an observation of a poor exposure and the GP moves away from it.

Optimizer restarts (``seed``, default 0).  Every fit runs L-BFGS-B from the kernel's initial
hyperparameters and from ``GP_RESTARTS`` points drawn uniformly in log space.  REF draws them
from NumPy's *global* random state, which advances from fit to fit, so it is not deterministic;
borealhdr mode draws them from one ``RandomState(seed)`` per instance that advances the same way
(``restart_seeding="stream"``), so a run equals REF run after ``np.random.seed(seed)``, draw for
draw.  Paper mode restarts every fit from ``RandomState(seed)`` (``"per-fit"``): a fit then
depends only on its window.  Why it matters: on real windows the start at the initial
hyperparameters often converges to a degenerate optimum (length scale at its 1e-5 bound, worse
log marginal likelihood), whose posterior mean vanishes off the data; its fine-grid argmax is
then index 0, a jump to 0.5 ms.  Only a restart that lands in the basin of the better optimum
avoids it; with "per-fit" the same ten points are reused for every window, so a window their
points all miss gives the jump every time, where REF, with fresh draws, usually avoids it.
The Gaussian process's helpers (repeat merging, the faster regressor) are
:mod:`emulator.autoexposure.kim_gp`.
"""

from __future__ import annotations

import math
import warnings

import cv2
import numpy as np

from emulator.autoexposure.base import MAX_DN, AutoExposureError, AutoExposureMethod, check_seed
from emulator.autoexposure.kim_exact import bin_sums, metric_ref_bins
from emulator.autoexposure.kim_gp import STEP_POOLS, fast_gpr_class, merge_repeats
from emulator.pools import single_thread_pools

__all__ = [
    "Kim2018",
    "ACTIVATION_ALPHA",
    "ACTIVATION_TAU",
    "ENTROPY_THRESHOLD",
    "GRID_MS",
    "N_COARSE",
    "N_FINE",
    "WINDOW",
    "GAMMA_MI_REF",
    "GAMMA_MI_PAPER",
    "ETA0",
    "SIGMA_STOP",
    "GP_NOISE",
    "GP_RESTARTS",
    "GP_BOUNDS",
    "GP_AMPLITUDE_BOUNDS_PAPER",
    "PAPER_SCALE",
    "RESTART_SEEDINGS",
    "metric_ref",
    "metric_paper",
    "softmax_weights",
    "local_entropy",
    "merge_repeats",
]

#: Activation slope alpha = 2^4 of pi = 2 / (1 + exp(-alpha H~ + tau)) - 1 (Kim's hytansigmoid).
ACTIVATION_ALPHA = 16.0
#: Activation offset tau = 2^2.
ACTIVATION_TAU = 4.0
#: Normalised entropy below which a pixel counts as saturated (REF's "Find value": untuned).
ENTROPY_THRESHOLD = 0.6
#: Exposure grid of the acquisition, ms.
GRID_MS = (0.5, 35.0)
#: Coarse grid points (acquisition) and fine grid points (final argmax of the GP mean).
N_COARSE = 50
N_FINE = 1000
#: Sliding window: the GP is fitted on at most this many (t, E) pairs.
WINDOW = 5
#: GP-MI exploration constant gamma = ln(2 / 0.25) (REF) ...
GAMMA_MI_REF = math.log(2 / 0.25)
#: ... and 7 in Kim's MATLAB (paper mode).
GAMMA_MI_PAPER = 7.0
#: Initial GP-MI eta (persists, grows by the chosen point's variance each frame).
ETA0 = 1.0
#: Posterior std (metric units) at or below which the GP mean's argmax is returned.
SIGMA_STOP = 5.0
#: Per-point GP noise variance alpha (a float: REF's ``np.full_like`` of an int list gives 0).
GP_NOISE = 0.2
#: Random restarts of the kernel-hyperparameter optimizer.
GP_RESTARTS = 10
#: Bounds of the constant and RBF length-scale hyperparameters.
GP_BOUNDS = (1e-5, 1e5)
#: Paper mode: bounds of the constant (amplitude) hyperparameter.  REF's 1e5 caps the prior
#: standard deviation at 316 metric units while E runs from 1e2 to 1e5; from the first frame
#: on, the posterior mean at the sampled exposure then exceeds the exploration bonus
#: everywhere and the method never leaves its starting exposure (measured: 4.00-4.02 ms over
#: 100 cycles on every synthetic scene).  With the amplitude free to reach E^2 the GP-MI
#: acquisition explores as Kim et al. intend.
GP_AMPLITUDE_BOUNDS_PAPER = (1e-5, 1e12)
#: Paper mode works on a 1/4-scale image, as Kim's MATLAB does.
PAPER_SCALE = 0.25
#: 12-bit to 8-bit: Y_8 = floor(Y / 16).
BIT_SHIFT = 4
#: Side of the local-entropy neighbourhood (paper mode).
LOCAL_ENTROPY_SIZE = 3
#: How the optimizer's restart points are drawn: "stream" (one RandomState(seed) per instance,
#: advanced by every fit, as REF's global state; borealhdr default) or "per-fit" (every fit
#: draws from a fresh RandomState(seed); paper default).
RESTART_SEEDINGS = ("stream", "per-fit")


def softmax_weights(q: np.ndarray, counts: np.ndarray | None = None) -> np.ndarray:
    """exp(q - max q) normalised so that sum(counts * W) = 1 (overflow-free REF weights)."""
    e = np.exp(q - np.max(q))
    total = np.sum(e if counts is None else counts * e)
    return e / total


def _activation(h_norm: np.ndarray, alpha: float, tau: float) -> np.ndarray:
    return 2.0 / (1.0 + np.exp(-alpha * h_norm + tau)) - 1.0


def _y8(y: np.ndarray) -> np.ndarray:
    """Y_8 = floor(Y / 16) as uint8 (REF's ``(Y / 16.0).astype(np.uint8)``), DN above 4095 clipped."""
    if int(y.max()) > MAX_DN:
        y = np.minimum(y, MAX_DN)
    return (y >> BIT_SHIFT).astype(np.uint8)


def _sobel_16u(img8: np.ndarray, dx: int, dy: int) -> np.ndarray:
    """``cv2.Sobel(img8, CV_16U, dx, dy, ksize=3)`` (negatives saturate to 0), via OpenCV's
    faster signed path: |Sobel| <= 1020 on 8-bit input fits int16 exactly."""
    g = cv2.Sobel(img8, cv2.CV_16S, dx, dy, ksize=3)
    np.maximum(g, 0, out=g)
    return g.view(np.uint16)


def _sobel_16u_xy(img8: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(_sobel_16u(img8, 1, 0), _sobel_16u(img8, 0, 1))`` in one pass: ``cv2.spatialGradient``
    is the 3x3 Sobel pair with the same default border (checked in the tests)."""
    if img8.shape[0] < 3 or img8.shape[1] < 3:  # spatialGradient's border needs 3 pixels
        return _sobel_16u(img8, 1, 0), _sobel_16u(img8, 0, 1)
    gx, gy = cv2.spatialGradient(img8, ksize=3, borderType=cv2.BORDER_DEFAULT)
    np.maximum(gx, 0, out=gx)
    np.maximum(gy, 0, out=gy)
    return gx.view(np.uint16), gy.view(np.uint16)


def metric_ref(y: np.ndarray, *, alpha=ACTIVATION_ALPHA, tau=ACTIVATION_TAU,
               threshold=ENTROPY_THRESHOLD) -> float:
    """REF's metric E of a gray image (uint16 DN), correctly rounded; NaN where REF divides by zero.

    Every per-pixel quantity of REF depends on the pixel only through its Y_8 bin (except Q),
    so E = sum_b W_b Q_b + mean(Q) sum_b n_b A_b M_b W_b over the 256 bins, with Q_b the exact
    integer sum of Q over bin b (:mod:`emulator.autoexposure.kim_exact`).  The 256-term arithmetic
    runs in 30-digit decimal (exp by :mod:`decimal`, ln from float64's log and one Newton step),
    so E is the exact value of REF's formula rounded once
    to float64: the same bits on every machine, BLAS and thread count.  Why it matters: GP-MI
    turns last-bit differences of E into different exposures (on a replay of the shared sample,
    a 1e-16 relative change of one frame's E moves cycle 10 from 9.099 to 9.168 ms), so any
    float64 evaluation order (a BLAS dot, NumPy's pairwise sums, whose rounding differs
    between versions and CPUs) makes the trajectory depend on the machine.
    """
    y8 = _y8(y)
    s = y8.size
    if s < 1 << 24:  # calcHist's float32 counts are exact
        counts = cv2.calcHist([y8], [0], None, [256], [0, 256]).ravel().astype(np.int64).tolist()
    else:
        counts = np.bincount(y8.ravel(), minlength=256).tolist()
    gx, gy = _sobel_16u_xy(y8)
    q_img = np.multiply(gx, gx, out=gx)  # uint16: wraps mod 65536 like REF
    q_img += np.multiply(gy, gy, out=gy)
    q_bin = bin_sums(y8, q_img)
    return metric_ref_bins(counts, q_bin, s, alpha, tau, threshold)


def local_entropy(img8: np.ndarray, size: int = LOCAL_ENTROPY_SIZE) -> np.ndarray:
    """Entropy (bits) of each pixel's size x size neighbourhood, 256 bins, symmetric padding.

    Like MATLAB's ``entropyfilt(I, true(size))``; float64, same shape.
    """
    r = size // 2
    pad = cv2.copyMakeBorder(img8, r, r, r, r, cv2.BORDER_REFLECT)
    h, w = img8.shape
    views = [pad[i : i + h, j : j + w] for i in range(size) for j in range(size)]
    n = len(views)
    table = np.zeros(n + 1)
    table[1:] = np.log2(np.arange(1, n + 1) / n) / n
    ent = np.zeros((h, w))
    for vj in views:
        c = np.zeros((h, w), dtype=np.uint8)
        for vk in views:
            c += vj == vk
        ent -= table[c]
    return ent


def metric_paper(y: np.ndarray, *, alpha=ACTIVATION_ALPHA, tau=ACTIVATION_TAU,
                 threshold=ENTROPY_THRESHOLD, scale=PAPER_SCALE) -> float:
    """Paper-mode metric E (local entropy, float gradients, Gaussian weight with minus sign).

    Always finite: a flat image scores E = 0 (no gradient), so the GP learns that this
    exposure is poor instead of skipping the frame as REF's guard must.
    """
    y8 = _y8(y)
    hh, ww = y8.shape
    small = cv2.resize(y8, (max(3, round(ww * scale)), max(3, round(hh * scale))), interpolation=cv2.INTER_AREA)
    ent = local_entropy(small).ravel()
    f = small.astype(np.float32)
    gx = cv2.Sobel(f, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(f, cv2.CV_32F, 0, 1, ksize=3)
    qv = (gx.astype(np.float64) ** 2 + gy.astype(np.float64) ** 2).ravel()
    mu = float(ent.mean())
    var = float(ent.var())
    h_lo, h_hi = float(ent.min()), float(ent.max())
    # Degenerate entropy (a flat image): the limits of the formulas, not NaN.  Equal entropies
    # give equal weights, and a flat image has Q = 0, so E = 0: "no gradient information".
    if var > 0.0:
        w = softmax_weights(-((ent - mu) ** 2) / (2.0 * var))
    else:
        w = np.full(ent.size, 1.0 / ent.size)
    h_norm = (ent - h_lo) / (h_hi - h_lo) if h_hi > h_lo else np.zeros_like(ent)
    act = _activation(h_norm, alpha, tau)
    mask = h_norm < threshold
    return float(np.dot(w, qv) + qv.mean() * np.dot(act * mask, w))


class Kim2018(AutoExposureMethod):
    """M_Kim (spec section 5).

    Parameters
    ----------
    mode : {"paper", "borealhdr"}
    seed : int
        ``random_state`` of the GP's optimizer restarts (same seed, same trajectory).
    window : int
        Sliding-window length L (:data:`WINDOW`).
    gamma_mi : float or None
        GP-MI constant (default ln 8 borealhdr, 7 paper).
    range_ms : (float, float) or None
        Optional output clamp, ms (the output is on [0.5, 35] anyway).
    gp_backend : {"fast", "sklearn"}
        "fast" (default): sklearn's regressor with a specialised log marginal likelihood
        (the same floating-point operations, so the same fits); "sklearn": the stock class.
    restart_seeding : {"stream", "per-fit"} or None
        Where the optimizer's restart points come from (module docstring): "stream" (default in
        borealhdr mode: one ``RandomState(seed)`` advanced by every fit, REF's behaviour) or
        "per-fit" (default in paper mode: every fit draws from a fresh ``RandomState(seed)``).
        :meth:`reset` restarts the stream.
    """

    name = "kim"
    seed_option = "seed"  # its GP's optimizer restarts are random draws

    def __init__(
        self,
        *,
        mode: str = "paper",
        range_ms="default",
        seed: int = 0,
        window: int = WINDOW,
        gamma_mi: float | None = None,
        eta0: float = ETA0,
        sigma_stop: float = SIGMA_STOP,
        gp_noise: float = GP_NOISE,
        gp_restarts: int = GP_RESTARTS,
        grid_ms: tuple[float, float] = GRID_MS,
        gp_backend: str = "fast",
        restart_seeding: str | None = None,
    ) -> None:
        super().__init__(mode=mode, range_ms=range_ms)
        if int(window) < 1:
            raise AutoExposureError(f"window must be >= 1, got {window!r}")
        lo, hi = (float(v) for v in grid_ms)
        if not (0 < lo < hi and math.isfinite(hi)):
            raise AutoExposureError(f"grid_ms must be (low, high) with 0 < low < high, got {grid_ms!r}")
        if gp_backend not in ("fast", "sklearn"):
            raise AutoExposureError(f"gp_backend must be 'fast' or 'sklearn', got {gp_backend!r}")
        self.gp_backend = gp_backend
        if restart_seeding is None:
            restart_seeding = "stream" if self.mode == "borealhdr" else "per-fit"
        if restart_seeding not in RESTART_SEEDINGS:
            raise AutoExposureError(f"restart_seeding must be one of {', '.join(RESTART_SEEDINGS)}, got {restart_seeding!r}")
        self.restart_seeding = restart_seeding
        self.seed = check_seed(seed)
        self.window = int(window)
        self.gamma_mi = float(gamma_mi if gamma_mi is not None else (GAMMA_MI_REF if self.mode == "borealhdr" else GAMMA_MI_PAPER))
        self.eta0 = float(eta0)
        self.sigma_stop = float(sigma_stop)
        self.gp_noise = float(gp_noise)
        self.gp_restarts = int(gp_restarts)
        self.grid_ms = (lo, hi)
        self.coarse = np.linspace(lo, hi, N_COARSE)
        self.fine = np.linspace(lo, hi, N_FINE)
        self._reset()

    def _reset(self) -> None:
        self.window_t: list[float] = []  # newest first
        self.window_e: list[float] = []
        self.eta = self.eta0
        # REF's global random state, seeded: advanced by every fit's restart draws.
        self._rng = np.random.RandomState(self.seed) if self.restart_seeding == "stream" else None

    def metric(self, y: np.ndarray) -> float:
        """The mode's metric E of a gray image (uint16); NaN for a degenerate image."""
        return metric_ref(y) if self.mode == "borealhdr" else metric_paper(y)

    def _fit(self):
        from sklearn.exceptions import ConvergenceWarning
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import RBF, ConstantKernel

        amplitude = GP_BOUNDS if self.mode == "borealhdr" else GP_AMPLITUDE_BOUNDS_PAPER
        kernel = ConstantKernel(1.0, amplitude) * RBF(1.0, GP_BOUNDS)
        cls = fast_gpr_class() if self.gp_backend == "fast" else GaussianProcessRegressor
        if self.mode == "borealhdr":  # REF: every window point as it is
            x, yv, alpha = (np.asarray(self.window_t, dtype=np.float64), np.asarray(self.window_e, dtype=np.float64),
                            np.full(len(self.window_t), self.gp_noise, dtype=np.float64))
        else:
            x, yv, alpha = merge_repeats(self.window_t, self.window_e, self.gp_noise)
        gp = cls(
            kernel=kernel,
            alpha=alpha,
            n_restarts_optimizer=self.gp_restarts,
            normalize_y=False,
            random_state=self._rng if self._rng is not None else self.seed,
        )
        x = x.reshape(-1, 1)
        with warnings.catch_warnings(), single_thread_pools(STEP_POOLS):
            warnings.simplefilter("ignore", ConvergenceWarning)
            warnings.simplefilter("ignore", RuntimeWarning)
            gp.fit(x, yv)
            mu, std = gp.predict(self.coarse.reshape(-1, 1), return_std=True)
        return gp, mu, std

    def update(self, t: float, metric: float) -> float:
        """One step of the controller for a frame at ``t`` ms with metric value ``metric``.

        Exposed so that the controller can run on an injected scalar metric (spec section 6).
        """
        self.last["metric"] = metric
        if not math.isfinite(metric):
            self.last["guard"] = "non-finite metric"
            self.guard_count += 1  # a fallback, recorded: the loop marks the cycle guarded
            return t
        self.window_t.insert(0, float(t))
        self.window_e.insert(0, float(metric))
        try:
            gp, mu, std = self._fit()
            if not (np.all(np.isfinite(mu)) and np.all(np.isfinite(std))):
                raise FloatingPointError("non-finite GP posterior")
        except (np.linalg.LinAlgError, ValueError, FloatingPointError, ArithmeticError) as exc:
            self.window_t.pop(0)
            self.window_e.pop(0)
            self.last["guard"] = f"GP fit failed: {exc}"
            self.guard_count += 1  # a fallback, recorded: the loop marks the cycle guarded
            return t
        var = std**2
        phi = math.sqrt(self.gamma_mi) * (np.sqrt(var + self.eta) - math.sqrt(self.eta))
        n = int(np.argmax(mu + phi))
        self.eta += float(var[n])
        if std[n] <= self.sigma_stop:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                fine_mu = gp.predict(self.fine.reshape(-1, 1))
            t_new = float(self.fine[int(np.argmax(fine_mu))]) if np.all(np.isfinite(fine_mu)) else t
            self.last["optimal"] = True
        else:
            t_new = float(self.coarse[n])
        if len(self.window_t) >= self.window:
            self.window_t.pop()
            self.window_e.pop()
        return t_new

    def _step(self, raw: np.ndarray, t: float) -> float:
        with single_thread_pools(STEP_POOLS):
            return self.update(t, self.metric(self.gray(raw)))

    def _options(self) -> dict:
        return {"seed": self.seed, "window": self.window, "gamma_mi": self.gamma_mi, "eta0": self.eta0,
                "sigma_stop": self.sigma_stop, "gp_noise": self.gp_noise, "gp_restarts": self.gp_restarts,
                "grid_ms": list(self.grid_ms), "gp_backend": self.gp_backend,
                "restart_seeding": self.restart_seeding}
