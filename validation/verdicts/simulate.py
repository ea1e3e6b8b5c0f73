"""Cheap synthetic metric tables (no renders) with known truth: what the verdicts are calibrated on.

One metric on ``W`` walks and ``M`` methods, in units of the metric::

    live[w, m]     = beta[m]   + a[w] + g[w, m]  + e1[w, m]
    control[w, m]  = beta[m]   + a[w] + g[w, m]  + e2[w, m]
    emulated[w, m] = beta_E[m] + a[w] + g_E[w, m] + e3[w, m]

``beta``: the methods' true effects (SD ``sd_method`` over the methods); ``a``: the walk
(scene, trajectory) level, common to every method; ``g``: walk x method interaction (a
method suits one walk better than another; SD ``sd_walk_method``), common to the
conditions run on the same walk; ``e``: the noise of one run (capture noise and the
closed loop's response to it; SD ``sd_noise``), drawn afresh for every run.

Emulators (``kind``):

* ``"live-draw"``: one more live draw (``beta_E = beta``, ``g_E = g``): a perfect emulator;
* ``"random"``: ranks at random (``beta_E`` a random permutation of ``beta``, ``g_E`` a
  fresh draw): the same spread, no relation to live;
* ``"tied"``: every method equal (``beta_E = 0``, ``g_E = 0``);
* ``"scaled"``: ``beta_E = beta + delta`` with ``delta`` a fresh draw of SD
  ``sqrt(omega2_true) * sd(beta)`` (the interaction of a given size on average: power);
* ``"exact"``: the same with ``delta`` centred and rescaled so that its variance over the
  methods is exactly ``omega2_true * var(beta)`` in every study (the true omega2 is
  ``omega2_true``: what an interval's coverage and the rule's error at the margin are
  measured on).

``interchangeable`` (the AE findings' null) draws ``beta = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from emulator.core.stats import rng_of

__all__ = ["Scales", "KINDS", "method_effects", "simulate_tables"]

KINDS = ("live-draw", "random", "tied", "scaled", "exact")


@dataclass(frozen=True)
class Scales:
    """Standard deviations of the components of one metric (its unit)."""

    sd_method: float = 1.0
    sd_walk_method: float = 0.5
    sd_noise: float = 1.0
    sd_walk: float = 1.0

    def __post_init__(self) -> None:
        for k in ("sd_method", "sd_walk_method", "sd_noise", "sd_walk"):
            if not getattr(self, k) >= 0:
                raise ValueError(f"{k} must be >= 0, got {getattr(self, k)}")


def method_effects(n_methods: int, sd: float) -> np.ndarray:
    """Fixed, evenly spaced method effects with SD ``sd`` over the methods (ddof 1), mean 0.

    Evenly spaced (not drawn) so that every calibration seed faces the same methods; the
    randomness is in the walks and runs.
    """
    b = np.linspace(-1.0, 1.0, n_methods)
    s = b.std(ddof=1)
    return b * (sd / s) if s > 0 else b


def simulate_tables(kind: str, n_walks: int, scales: Scales, *, n_methods: int = 7, n_seeds: int = 1, seed=0,
                    omega2_true: float = 0.0, beta: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Tables ``live``, ``emulated``, ``control`` of shape (n_seeds, n_walks, n_methods).

    ``beta`` overrides the method effects (:func:`method_effects` by default).
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    rng = rng_of(seed)
    b = method_effects(n_methods, scales.sd_method) if beta is None else np.asarray(beta, dtype=np.float64)
    shape = (n_seeds, n_walks, n_methods)
    a = rng.normal(0.0, scales.sd_walk, (n_seeds, n_walks, 1))
    g = rng.normal(0.0, scales.sd_walk_method, shape)
    live = b + a + g + rng.normal(0.0, scales.sd_noise, shape)
    control = b + a + g + rng.normal(0.0, scales.sd_noise, shape)
    if kind == "live-draw":
        be, ge = np.broadcast_to(b, shape), g
    elif kind == "random":
        be = np.stack([rng.permutation(b) for _ in range(n_seeds)])[:, None, :]
        ge = rng.normal(0.0, scales.sd_walk_method, shape)
    elif kind == "tied":
        be, ge = 0.0, 0.0
    else:
        sd_b = b.std(ddof=1) if b.size > 1 else 0.0
        delta = rng.normal(0.0, np.sqrt(omega2_true) * sd_b, (n_seeds, 1, n_methods))
        if kind == "exact":
            delta = delta - delta.mean(axis=-1, keepdims=True)
            sd_d = delta.std(axis=-1, ddof=1, keepdims=True)
            delta = np.where(sd_d > 0, delta / np.where(sd_d > 0, sd_d, 1.0), 0.0) * np.sqrt(omega2_true) * sd_b
        be = b + delta
        ge = g
    emulated = be + a + ge + rng.normal(0.0, scales.sd_noise, shape)
    return {"live": live, "emulated": emulated, "control": control}
