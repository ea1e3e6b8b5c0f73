"""Per-method cost of the seven AE methods on full-resolution BorealHDR frames.

Usage: python benchmarks/bench_autoexposure.py [SEQUENCE] [--repeat N] [--frames N]

For each method and mode, the median milliseconds of ``next_exposure`` on 1920x1200 frames
of the sample (after a warm-up call), next to a straightforward per-pixel implementation of
the published reference code (REF, as spec sections 1-5 describe it: per-pixel float
arithmetic, ``cv2.Sobel(..., CV_16U)`` images, ``scipy.signal.convolve2d``, the spline
evaluated at every pixel, an ``argsort`` in extended precision, the stock sklearn regressor).
The REF-style versions double as a check: their exposures must equal exposim's borealhdr
mode (printed as the largest relative difference).  The REF-style functions are reused by
``bench_playback.py`` for its naive baseline.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
import warnings
from pathlib import Path

import cv2
import numpy as np

from emulator.autoexposure import METHOD_NAMES, METHODS
from emulator.io.borealhdr import load_sequence, sequence_response
from _timing import SAMPLE_SEQ, median_ms

DEFAULT_SEQ = SAMPLE_SEQ


# ============================================================================ REF-style
class RefClassical:
    """Spec section 1 as REF computes it."""

    def __init__(self, percent=50):
        self.name = f"classical-{percent}"
        self.target = int((percent / 100) * 2**12)

    def reset(self):
        pass

    def next_exposure(self, raw, t):
        y = cv2.cvtColor(raw, cv2.COLOR_BAYER_RG2GRAY)
        e = np.mean(y) - self.target
        if abs(e) < 15:
            return t
        return float(abs(t + 0.002 * abs(e))) if e < 0 else float(abs(t - 0.002 * abs(e)))


class RefFixed:
    name = "fixed"

    def __init__(self):
        self.inner, self.count = RefClassical(50), 0

    def reset(self):
        self.count = 0

    def next_exposure(self, raw, t):
        if self.count <= 3:
            self.count += 1
            return self.inner.next_exposure(raw, t)
        return t


class RefShim:
    """Spec section 3 (REF): per-pixel, CV_16U Sobel, float32 gradient image."""

    name = "shim"
    gammas = np.array([1 / 1.9, 1 / 1.5, 1 / 1.2, 1.0, 1.2, 1.5, 1.9])

    def reset(self):
        pass

    def next_exposure(self, raw, t):
        y = cv2.cvtColor(raw, cv2.COLOR_BAYER_RG2GRAY)
        if y.max() == y.min():  # the guard (REF would take index 0 of an all-NaN fit)
            g_hat = 1 / 1.9 if y.mean() < 2048 else 1.9
        else:
            norm = (y - np.min(y)) / (np.max(y) - np.min(y))
            n = np.log10(1e3 * (1 - 0.06) + 1)
            metrics = []
            for g in self.gammas:
                img = norm**g
                gx = cv2.Sobel(img, ddepth=cv2.CV_16UC1, dx=1, dy=0, ksize=3)
                gy = cv2.Sobel(img, ddepth=cv2.CV_16UC1, dx=0, dy=1, ksize=3)
                grad = np.sqrt(gx**2 + gy**2)
                with np.errstate(invalid="ignore"):
                    m = (grad - np.min(grad)) / (np.max(grad) - np.min(grad))
                mbar = np.zeros_like(m)
                sel = m >= 0.06
                mbar[sel] = (1 / n) * np.log10(1e3 * (m[sel] - 0.06) + 1)
                metrics.append(np.sum(mbar))
            metrics = np.asarray(metrics, dtype=np.float64)
            if np.ptp(metrics) <= 1e-9 * max(1.0, np.abs(metrics).max()):
                g_hat = 1 / 1.9 if y.mean() < 2048 else 1.9
            else:
                fit = np.poly1d(np.polyfit(self.gammas, metrics, deg=5))
                grid = np.linspace(self.gammas.min(), self.gammas.max(), 100)
                g_hat = grid[np.argmax(fit(grid))]
        alpha = 0.5 if g_hat >= 1 else 1.0
        return float((1 + alpha * 0.2 * (1 - g_hat)) * t)


class RefZhang:
    """Spec section 4 (REF): convolve2d, per-pixel spline, argsort in extended precision."""

    name = "zhang"

    def __init__(self, knots):
        from scipy.interpolate import UnivariateSpline, interp1d

        e = 16.0 * np.asarray(knots, dtype=np.float64)
        e[0], e[-1] = 0.0, 4095.0
        icrf = interp1d(np.linspace(0, 4095, 256), e, kind="linear")
        delta = np.diff(icrf(np.linspace(0, 4095, 4097)))
        self.h = UnivariateSpline(np.arange(4096), delta)
        self.weights = None
        self.classical = RefClassical(50)

    def reset(self):
        pass

    def _weights(self, s, p=0.8, k=5):
        if self.weights is None or self.weights.size != s:
            tau = math.floor(p * s)
            i = np.arange(s)
            w = np.zeros(s)
            w[:tau] = np.sin(np.pi / (2 * tau) * i[:tau]) ** k
            w[tau:] = np.sin(np.pi / 2 - np.pi / (2 * (s - tau)) * (i[tau:] - tau)) ** k
            self.weights = w / np.linalg.norm(w)
        return self.weights

    def next_exposure(self, raw, t):
        from scipy import signal

        y = cv2.cvtColor(raw, cv2.COLOR_BAYER_RG2GRAY)
        mu = np.mean(y)
        if mu <= 1120 or mu >= 3040:
            nxt = self.classical.next_exposure(raw, t)
        else:
            kx = np.array([[3, 0, -3], [10, 0, -10], [3, 0, -3]])
            ky = np.array([[3, 10, 3], [0, 0, 0], [-3, -10, -3]])
            yf = y.astype(np.float64)
            ix = signal.convolve2d(yf, kx, mode="same", boundary="symm")
            iy = signal.convolve2d(yf, ky, mode="same", boundary="symm")
            dmap = 1.0 / (self.h(yf) * t)
            dx = signal.convolve2d(dmap, kx, mode="same", boundary="symm")
            dy = signal.convolve2d(dmap, ky, mode="same", boundary="symm")
            d = (2 * (ix * dx + iy * dy)).ravel().astype(np.longdouble)
            order = np.argsort(d)
            w = self._weights(d.size) * math.sqrt(1200 * 1920 / d.size)
            nxt = t + 1e-6 * float(np.sum(w.astype(np.longdouble) * d[order]))
        return float(max(nxt, 0.02))


class RefKim:
    """Spec section 5 (REF): per-pixel entropy and weights, stock sklearn regressor (seeded)."""

    name = "kim"

    def __init__(self, seed=0):
        self.seed = seed
        self.reset()

    def reset(self):
        self.ts, self.es, self.eta = [], [], 1.0

    def metric(self, raw):
        y = cv2.cvtColor(raw, cv2.COLOR_BAYER_RG2GRAY)
        img = (y / 16.0).astype(np.uint8)
        hist, _ = np.histogram(img.ravel(), bins=256, range=(0, 256))
        p = hist / hist.sum()
        ent = -p[img.ravel()] * np.log2(p[img.ravel()])
        gx = cv2.Sobel(img, ddepth=cv2.CV_16UC1, dx=1, dy=0, ksize=3).ravel()
        gy = cv2.Sobel(img, ddepth=cv2.CV_16UC1, dx=0, dy=1, ksize=3).ravel()
        q = gx**2 + gy**2
        sigma = np.std(ent)
        if not sigma > 0 or ent.max() == ent.min():
            return math.nan
        z = (ent - np.mean(ent)) ** 2 / (2 * sigma**2)
        w = np.exp(z - z.max())  # REF's exp(+z) / sum, overflow-free
        w = w / np.sum(w)
        h = (ent - ent.min()) / (ent.max() - ent.min())
        act = 2 / (1 + np.exp(-16 * h + 4)) - 1
        mask = np.zeros_like(h)
        mask[h < 0.6] = 1
        return float(np.sum(w * q + act * mask * w * (1 / q.size) * np.sum(q)))

    def next_exposure(self, raw, t):
        from sklearn.exceptions import ConvergenceWarning
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import RBF

        e = self.metric(raw)
        if not math.isfinite(e):
            return t
        self.ts.insert(0, t)
        self.es.insert(0, e)
        grid = np.linspace(0.5, 35, 50)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            gp = GaussianProcessRegressor(kernel=1.0 * RBF(), alpha=np.full(len(self.ts), 0.2),
                                          n_restarts_optimizer=10, random_state=self.seed)
            gp.fit(np.array(self.ts).reshape(-1, 1), np.array(self.es))
            mu, std = gp.predict(grid.reshape(-1, 1), return_std=True)
        var = std**2
        phi = np.sqrt(np.log(8)) * (np.sqrt(var + self.eta) - np.sqrt(self.eta))
        n = int(np.argmax(mu + phi))
        self.eta += var[n]
        if std[n] <= 5:
            fine = np.linspace(0.5, 35, 1000)
            nxt = fine[np.argmax(gp.predict(fine.reshape(-1, 1)))]
        else:
            nxt = grid[n]
        if len(self.ts) == 5:
            self.ts.pop()
            self.es.pop()
        return float(nxt)


def ref_methods(response) -> dict:
    """name -> a fresh REF-style method (borealhdr semantics, no clamp)."""
    return {
        "fixed": RefFixed(),
        "classical-30": RefClassical(30),
        "classical-50": RefClassical(50),
        "classical-70": RefClassical(70),
        "shim": RefShim(),
        "zhang": RefZhang(response.knots),
        "kim": RefKim(),
    }


# ============================================================================ bench

def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequence", nargs="?", type=Path, default=DEFAULT_SEQ)
    ap.add_argument("--repeat", type=int, default=5, help="calls per method and frame (median)")
    ap.add_argument("--frames", type=int, default=3, help="frames of the sample (left camera, cycle 1)")
    ap.add_argument("--skip-ref", action="store_true", help="skip the slow REF-style versions")
    args = ap.parse_args(argv)

    seq = load_sequence(args.sequence)
    response = sequence_response(seq)
    cycle = seq[1]
    frames = [cycle.frames["left"][b].load() for b in (4.0, 8.0, 16.0, 2.0, 1.0, 32.0)[: args.frames]]
    exposures = (4.0, 8.0, 16.0, 2.0, 1.0, 32.0)[: args.frames]
    gray_ms = median_ms(lambda: cv2.cvtColor(frames[0], cv2.COLOR_BayerRG2GRAY), 10)
    print(f"frames: {len(frames)} x {frames[0].shape[1]}x{frames[0].shape[0]} from {seq.path.name}, cycle 1 "
          f"({', '.join(f'{e:g}' for e in exposures)} ms); gray conversion alone {gray_ms:.1f} ms")
    print(f"{'method':13s} {'mode':9s} {'ms/frame':>9s} {'REF-style':>10s} {'speed-up':>9s}  max rel. diff to REF")
    refs = {} if args.skip_ref else ref_methods(response)
    results = {}
    for name in METHOD_NAMES:
        for mode in ("borealhdr", "paper"):
            kw = {"response": response} if name == "zhang" else {}

            def fresh():
                return METHODS[name](mode=mode, range_ms=None, **kw)

            ms = _per_frame_ms(fresh(), frames, exposures, args.repeat, reset=name == "fixed")
            ref_txt, diff_txt, speed = "", "", ""
            row = {"ms_per_frame": ms}
            if mode == "borealhdr" and name in refs:
                rms = _per_frame_ms(refs[name], frames, exposures, max(1, args.repeat // 2), reset=name == "fixed")
                # same frames, same order, fresh instances: the exposures must agree
                m2, r2 = fresh(), ref_methods(response)[name]
                outs = [m2.next_exposure(raw, t) for raw, t in zip(frames, exposures)]
                routs = [r2.next_exposure(raw, t) for raw, t in zip(frames, exposures)]
                diff = max(abs(a - b) / max(abs(b), 1e-12) for a, b in zip(outs, routs))
                ref_txt, speed, diff_txt = f"{rms:10.1f}", f"{rms / ms:8.1f}x", f"{diff:.1e}"
                row.update(ref_ms_per_frame=rms, max_rel_diff=diff)
            results[(name, mode)] = row
            print(f"{name:13s} {mode:9s} {ms:9.1f} {ref_txt:>10s} {speed:>9s}  {diff_txt}")
            sys.stdout.flush()
    return results


def _per_frame_ms(method, frames, exposures, repeat, reset=False):
    """Median ms of next_exposure over frames x repeat, after one warm-up call; state carries
    over between calls (kim's window fills as in a run) unless ``reset``."""
    method.next_exposure(frames[0], exposures[0])
    times = []
    for _ in range(repeat):
        for raw, t in zip(frames, exposures):
            if reset:
                method.reset()
            t0 = time.perf_counter()
            method.next_exposure(raw, t)
            times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


if __name__ == "__main__":
    main()
