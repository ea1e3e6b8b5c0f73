"""M_Kim's Gaussian process (:mod:`emulator.autoexposure.kim`): window points merged at equal
exposures (:func:`merge_repeats`) and a regressor with a faster, bit-identical log marginal
likelihood (:func:`fast_gpr_class`).

SciPy and scikit-learn are imported when the first fit needs them, not with this module.
"""

from __future__ import annotations

import numpy as np

__all__ = ["merge_repeats", "fast_gpr_class", "STEP_POOLS"]


def merge_repeats(t, e, noise: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Window points at the same exposure merged: (exposures, mean metric, noise / count), first-seen order.

    k observations y_i = f(t) + e_i, e_i ~ N(0, noise), at one exposure carry the same information
    about f as their mean with noise / k: the posterior is identical, and the log marginal likelihood
    differs by a term that does not depend on the kernel's hyperparameters, so the best fit is the
    same.  Numerically they are not the same: two equal rows in K (exposure clamped at the grid end
    twice, or an unchanged proposal) with a noise of 0.2 against metric values of 1e3-1e4 make K
    near-singular (condition ~ amplitude / 0.2 up to 5e12) and the likelihood a flat plateau around
    -(y_1 - y_2)^2 / (4 noise), about -2.6e6 on a real window, where the optimizer stops anywhere
    and its stopping point follows SciPy's L-BFGS-B implementation (measured: the paper-mode
    trajectory on the upstream sample parted at cycle 6 between SciPy 1.14 and 1.17).
    """
    xs: list[float] = []
    sums: list[float] = []
    counts: list[int] = []
    for ti, ei in zip(t, e):
        ti = float(ti)
        if ti in xs:
            j = xs.index(ti)
            sums[j] += float(ei)
            counts[j] += 1
        else:
            xs.append(ti)
            sums.append(float(ei))
            counts.append(1)
    c = np.asarray(counts, dtype=np.float64)
    return np.asarray(xs), np.asarray(sums) / c, float(noise) / c


_FAST_GPR = None  # the class, made once
#: Every step runs under one BLAS/OpenMP thread (:mod:`emulator.pools`): the optimizer's tiny
#: BLAS calls are ~7x slower with a thread pool on a busy machine (measured), and GP-MI
#: amplifies a multi-threaded BLAS's last-bit differences into other exposures.  SciPy and
#: scikit-learn are loaded first, so their pools are covered too.
STEP_POOLS = ("scipy.linalg", "sklearn.gaussian_process")


def fast_gpr_class():
    """A ``GaussianProcessRegressor`` whose log marginal likelihood, for the Constant x RBF
    kernel of M_Kim, skips sklearn's per-call kernel machinery.

    It performs the same floating-point operations as sklearn 1.x (``ConstantKernel``,
    ``RBF.__call__``, ``Product.__call__`` and ``log_marginal_likelihood``, with LAPACK's
    potrf / potrs called directly), so fits are identical (checked against the stock class
    in the tests); on the 5-point windows, where sklearn's and scipy's Python overhead
    dominates, it is several times faster.  Any other call goes to sklearn.
    """
    global _FAST_GPR
    if _FAST_GPR is not None:
        return _FAST_GPR
    from scipy.linalg.lapack import dpotrf, dpotrs
    from sklearn.gaussian_process import GaussianProcessRegressor

    class FastGPR(GaussianProcessRegressor):
        def log_marginal_likelihood(self, theta=None, eval_gradient=False, clone_kernel=True):
            x = self.X_train_
            if (theta is None or not eval_gradient or clone_kernel or x.ndim != 2 or x.shape[1] != 1
                    or self.y_train_.ndim != 1):
                return super().log_marginal_likelihood(theta, eval_gradient, clone_kernel)
            theta = np.asarray(theta, dtype=np.float64)
            c = np.exp(theta[0])
            length = np.squeeze(np.exp(theta[1])).astype(float)
            xs = (x / length)[:, 0]
            dists = xs[:, np.newaxis] - xs[np.newaxis, :]
            dists *= dists  # = scipy's pdist 'sqeuclidean' for one feature, squareform'ed
            k2 = np.exp(-0.5 * dists)
            n = xs.size
            k1 = np.full((n, n), c)
            k_grad = np.empty((n, n, 2))
            k_grad[:, :, 0] = k1 * k2  # ConstantKernel gradient (= c) times the RBF matrix
            k_grad[:, :, 1] = (k2 * dists) * k1  # RBF gradient times the constant matrix
            k = k1 * k2
            k[np.diag_indices_from(k)] += self.alpha
            chol, info = dpotrf(k, lower=1, clean=1, overwrite_a=1)
            if info != 0:
                return -np.inf, np.zeros_like(theta)
            y = self.y_train_[:, np.newaxis]
            alpha, info = dpotrs(chol, y, lower=1)
            lml = -0.5 * np.einsum("ik,ik->k", y, alpha)
            lml -= np.log(np.diag(chol)).sum()
            lml -= n / 2 * np.log(2 * np.pi)
            inner = np.einsum("ik,jk->ijk", alpha, alpha)
            k_inv, info = dpotrs(chol, np.eye(n), lower=1)
            inner -= k_inv[..., np.newaxis]
            grad = 0.5 * np.einsum("ijl,jik->kl", inner, k_grad)
            return lml.sum(axis=-1), grad.sum(axis=-1)

    _FAST_GPR = FastGPR
    return FastGPR
