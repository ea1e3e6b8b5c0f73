"""Markdown tables of method comparisons with intervals (:func:`emulator.core.stats.compare_methods`)."""

from __future__ import annotations

__all__ = ["comparison_table", "mark_trending"]


def _f(v, spec: str, scale: float) -> str:
    return "-" if v is None else format(scale * v, spec)


def _iv(iv, spec: str, scale: float) -> str:
    return "-" if not iv else f"[{_f(iv[0], spec, scale)}, {_f(iv[1], spec, scale)}]"


def comparison_table(comparison: dict, label: str, *, spec: str = ".3g", scale: float = 1.0) -> list[str]:
    """A markdown table: per method the statistic and its 95 % interval, and its difference from the best
    method with its interval ("cannot tell apart" when the interval holds 0).  ``scale`` multiplies every
    figure (e.g. 100 for percent)."""
    best = comparison.get("best")
    lines = [f"| method | {label} | 95 % interval | difference from the best ({best}) | 95 % interval | verdict |",
             "| --- | ---: | --- | ---: | --- | --- |"]
    for m, r in comparison["methods"].items():
        d = r.get("difference_to_best")
        if m == best:
            verdict = "best"
        elif d is None or d.get("excludes_zero") is None:
            verdict = "-"
        else:
            verdict = "differs" if d["excludes_zero"] else "cannot tell apart"
        lines.append(f"| {m} | {_f(r['estimate'], spec, scale)} | {_iv(r['ci95'], spec, scale)} | "
                     f"{_f(None if d is None else d['estimate'], spec, scale)} | "
                     f"{_iv(None if d is None else d['ci95'], spec, scale)} | {verdict} |")
    return lines


def mark_trending(comparison: dict, trending: dict) -> dict:
    """``comparison`` with the methods still trending at the end of the run (``{name: {"direction": ...}}``,
    :func:`emulator.core.settling.trending_methods`) renamed ``name (still rising)``, so that a "best" or
    "differs" beside them reads as the transient it is."""
    if not trending:
        return comparison

    def name(m):
        return f"{m} (still {trending[m]['direction']})" if m in trending else m

    best = comparison.get("best")
    return {**comparison, "best": None if best is None else name(best),
            "methods": {name(m): r for m, r in comparison["methods"].items()}}
