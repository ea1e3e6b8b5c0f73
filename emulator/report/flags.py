"""What a run emulated from less than a full sweep: :func:`run_flags` (``results.json``'s ``flags``) and
:func:`flags_markdown` (the Flags section of ``report.md``, :mod:`emulator.report.run`).

Partial cycles (a bracket missing on either camera) and large upward ratios (above
:data:`~emulator.core.emulate.UPWARD_RATIO_FLAG`) are flagged; a run with neither has no flags.
"""

from __future__ import annotations

import numpy as np

from emulator.cells import DASH, format_number
from emulator.core.dataset import missing_text
from emulator.core.emulate import UPWARD_RATIO_FLAG

__all__ = ["run_flags", "flags_markdown"]


def run_flags(info: dict, tables: dict) -> dict | None:
    """What a run emulated from less than a full sweep, or None when nothing needs a flag.

    ``partial_cycles``: the recording's cycles missing a bracket on either camera, with what
    was missing (``run.json``); per method, how many of its cycles were partial, how many
    were emulated upwards by more than :data:`~emulator.core.emulate.UPWARD_RATIO_FLAG`, and its
    largest upward ratio (None when it never emulated upwards).
    """
    partial = list(info.get("partial_cycles") or [])
    partial_set = {int(p["cycle"]) for p in partial}
    per_method = {}
    for name, t in tables.items():
        ratio = np.asarray(t["ratio"], dtype=float)
        up = ratio[ratio > 1.0]
        per_method[name] = {
            "partial_cycles_used": int(sum(int(c) in partial_set for c in t.get("recorder_cycle", t["cycle"]))),
            "cycles_above_ratio_bound": int(np.sum(ratio > UPWARD_RATIO_FLAG)),
            "worst_upward_ratio": float(up.max()) if up.size else None,
        }
    if not partial and not any(m["cycles_above_ratio_bound"] for m in per_method.values()):
        return None
    skipped = {int(s["cycle"]) for s in info.get("skipped_cycles") or [] if isinstance(s, dict)}
    return {
        "upward_ratio_bound": UPWARD_RATIO_FLAG,
        "partial_cycles": partial,
        "partial_cycles_skipped": sum(int(p["cycle"]) in skipped for p in partial),
        "methods": per_method,
    }


def flags_markdown(flags: dict, unit: str = "cycles") -> list[str]:
    """The report's section on partial cycles and large upward ratios (``unit``: what a row of the run is,
    ``cycles`` or, at native rate, ``frames``)."""
    bound = flags["upward_ratio_bound"]
    partial = flags["partial_cycles"]
    lines = ["", "Flags (partial cycles and large upward ratios):", ""]
    if partial:
        lines.append(f"Partial cycles (a bracket missing on either camera): {len(partial)}"
                     + (f", {flags['partial_cycles_skipped']} of them left out (--skip-partial)"
                        if flags["partial_cycles_skipped"] else
                        "; their images come from the brackets that are there (--skip-partial leaves them out)"))
        lines += [f"- cycle {p['cycle']}: {missing_text(p['missing'])}" for p in partial]
        lines.append("")
    lines += [f"Emulating up by a ratio k stretches one bracket DN into k DN and raises the noise by about sqrt(k); "
              f"ratios above {bound:g} are flagged (with brackets a factor 2 apart and the default clamp, a "
              "complete sweep never needs more than 2).", "",
              f"| method | {unit} from partial cycles | {unit} with ratio > {bound:g} | largest upward ratio |",
              "| --- | ---: | ---: | ---: |"]
    lines += [f"| {n} | {m['partial_cycles_used']} | {m['cycles_above_ratio_bound']} | "
              f"{format_number(m['worst_upward_ratio'], '.3g', missing=DASH)} |" for n, m in flags["methods"].items()]
    return lines
