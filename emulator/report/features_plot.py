"""Paper Fig. 4 of the feature benchmark: (a) uniformity, (b) matches, (c) success against tau.

Drawn from the ``results.json`` of :func:`emulator.metrics.bench.bench_features`, so it can be
redrawn without recomputing; re-exported by :mod:`emulator.report.bench`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from emulator.report.figures import legend_outside, new_figure, plural, same_as, save

__all__ = ["features_figure", "plot_features", "weakest_pairs"]


def _boxplot(ax, data: list, labels: list[str]) -> None:
    present = [(d, name) for d, name in zip(data, labels) if len(d)]
    if not present:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        return
    values, names = zip(*present)
    ax.boxplot(values, tick_labels=names, showfliers=True)
    ax.tick_params(axis="x", labelrotation=30)


def weakest_pairs(results: dict) -> dict[str, list[int]]:
    """Per method, the match count of its weakest consecutive pair in each run that has a pair
    (what the success rate is made of: a run succeeds for every tau up to it), in run order."""
    out = {}
    for m in results["methods"]:
        per_run = [min(run["methods"][m]["matches"]) for run in results["runs"]
                   if run["methods"].get(m, {}).get("matches")]
        if per_run:
            out[m] = per_run
    return out


def _success_bars(c, weakest: dict[str, list[int]], methods: list[str]) -> None:
    """Panel (c) over one run: a run's success rate is 100 % up to its weakest pair and 0 beyond,
    so each method's weakest pair is drawn as a bar, its count written on it."""
    names = [m for m in methods if m in weakest]
    values = [weakest[m][0] for m in names]
    bars = c.bar(range(len(names)), values, color=[f"C{methods.index(m) % 10}" for m in names])
    c.bar_label(bars, labels=[str(v) for v in values], fontsize="small", padding=2)
    c.set_xticks(range(len(names)), names, rotation=30)
    c.axhline(100, color="0.6", lw=0.8, ls=":", zorder=0)  # the paper's reference threshold
    c.set_ylabel("matches of the weakest consecutive pair")
    c.set_ylim(0, 1.12 * max(values + [100]))
    c.set_title("(c) weakest pair: the run succeeds for every\n"
                r"$\tau_\mathrm{matches}$ up to it (dotted: 100, the paper's)", fontsize="medium")


def _success_curves(c, results: dict, weakest: dict[str, list[int]], methods: list[str]) -> None:
    """Panel (c) over several runs: the success rate against tau.  A curve identical to an earlier
    one on the tau grid is drawn dashed over it; it is named equal ("= name") only when the two
    methods' weakest pairs are equal run for run (so the curves are equal at every tau), else
    "hides name's curve" (equal on the grid only)."""
    curve = results["success_curve"]
    rates = {m: curve["rate"][m] for m in methods if curve["rate"].get(m) is not None}
    on_grid = same_as(rates)
    equal = same_as({m: weakest[m] for m in rates if m in weakest})
    taus = list(curve["taus"])
    step = taus[-1] - taus[-2] if len(taus) > 1 else 1
    x = taus + [taus[-1] + step] if taus else taus  # the last step drawn to its end
    for m, rate in rates.items():
        y = 100.0 * np.append(rate, rate[-1]) if taus else []
        if m in on_grid:  # drawn dashed over its twin: identical curves hide each other
            tag = f"= {on_grid[m]}" if equal.get(m) == on_grid[m] else f"hides {on_grid[m]}'s curve"
            c.plot(x, y, ls="--", label=f"{m} ({tag})", drawstyle="steps-post")
        else:
            c.plot(x, y, label=m, drawstyle="steps-post")
    if taus:
        c.set_xlim(0, x[-1])
    c.axvline(100, color="0.6", lw=0.8, ls=":", zorder=0)  # the paper's reference threshold
    c.set_xlabel(r"$\tau_\mathrm{matches}$ (dotted: 100, the paper's)")
    c.set_ylabel("successful runs (%)")
    c.set_ylim(-2, 102)
    c.set_title(f"(c) success rate over {plural(results['n_runs'], 'run folder')}")
    legend_outside(c)


def features_figure(results: dict):
    """The figure of :func:`plot_features` (a matplotlib Figure with three axes)."""
    methods = list(results["methods"])
    uniformity = [[100.0 * u for run in results["runs"] for u in run["methods"].get(m, {}).get("uniformity", [])]
                  for m in methods]
    matches = [[c for run in results["runs"] for c in run["methods"].get(m, {}).get("matches", [])] for m in methods]
    fig, (a, b, c) = new_figure(3)
    _boxplot(a, uniformity, methods)
    a.set_ylabel("grid cells with a keypoint (%)")
    rows, cols = results["parameters"]["grid"]
    a.set_title(f"(a) uniformity, {rows}x{cols} grid")
    _boxplot(b, matches, methods)
    b.set_ylabel("matches between consecutive images")
    b.set_title(f"(b) matches (ratio test {results['parameters']['ratio']})")
    weakest = weakest_pairs(results)
    if not weakest:
        c.text(0.5, 0.5, "no data", ha="center", va="center", transform=c.transAxes)
        c.set_title("(c) success rate")
    elif len(results["runs"]) == 1:
        _success_bars(c, weakest, methods)
    else:
        _success_curves(c, results, weakest, methods)
    return fig


def plot_features(results: dict, path: str | Path) -> Path:
    """Paper Fig. 4: (a) uniformity, (b) matches per pair, (c) success rate against tau.

    Over one run folder the success rate of a method is a step from 100 % to 0 at its weakest
    pair, so panel (c) shows each method's weakest pair instead.

    Parameters
    ----------
    results : dict
        The ``results.json`` of the feature benchmark.
    path : str or pathlib.Path
        PNG to write.
    """
    return save(features_figure(results), path)
