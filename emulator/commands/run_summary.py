"""What ``exposim run`` prints at the end of a run: the summary lines, or the summary as JSON."""

from __future__ import annotations

import sys

from emulator.core.native import is_native_run
from emulator.io.files import strict_json

__all__ = ["print_run_summary"]


def print_run_summary(args, summary: dict) -> int:
    """Print a run's summary (or its JSON with ``--json``); the exit code (1 when a method failed and ``--strict``)."""
    failed = {n: m["status"] for n, m in summary["methods"].items() if m.get("status", "ok").startswith("failed")}
    rc = 1 if failed and args.strict else 0
    if args.json:
        print(strict_json(summary, indent=1), file=getattr(args, "json_stream", None) or sys.stdout)
        return rc
    print(f"run folder  {args.output}")
    native = is_native_run(summary)
    print(f"frames      {summary['cycles_done']}/{summary.get('n_frames')} (native rate)" if native else
          f"cycles      {summary['cycles_done']}/{summary['n_cycles']}"
          + (f" ({len(summary['skipped_cycles'])} skipped)" if summary["skipped_cycles"] else ""))
    for name, m in summary["methods"].items():
        mean = m["mean_exposure_ms"]
        print(f"  {name:13s} mean {mean:8.3f} ms  next (after last frame) {m['final_exposure_ms']:8.3f} ms  "
              f"sat {m['mean_saturated_fraction']:.2%}" if mean is not None else f"  {name:13s} no cycle")
    _print_flags(summary.get("flags"), "frame" if native else "cycle")
    for name, t in (summary.get("still_trending") or {}).items():
        print(f"unsettled   {name} still {t['direction']} at the end ({100 * abs(t['change_fraction']):.0f} % over the "
              f"last {t['steps']} recorder cycles): too short a clip to rank it")
    if summary.get("gyro_note"):  # known at the end (a full /dev/shm was said before the first cycle)
        print(f"exposim run: warning: {summary['gyro_note']}", file=sys.stderr)
    timing = summary.get("timing") or {}
    if timing.get("cycles_per_s"):
        steady = timing.get("steady_cycles_per_s")
        print(f"speed       {timing['cycles_per_s']:.2f} {'frames' if native else 'cycles'}/s"
              + (f" ({steady:.2f} after start-up, {timing['startup_s']:.2f} s)" if steady else ""))
    if failed:
        print(f"FAILED      {len(failed)} of {len(summary['methods'])} method(s); the others' results are complete"
              + (" (--strict: exit code 1)" if args.strict else ""))
        for name, why in failed.items():
            print(f"  {name:13s} {why}")
    if (args.output / "report.html").is_file():
        print(f"report      {args.output / 'report.html'} (open in a browser)")
    return rc


def _print_flags(flags: dict | None, unit: str = "cycle") -> None:
    """The report's flags in one or two lines (nothing when nothing was flagged); ``unit``: a row of the run."""
    if flags is None:
        return
    partial = flags["partial_cycles"]
    if partial:
        skipped = flags["partial_cycles_skipped"]
        print(f"partial     {len(partial)} cycle(s) missing brackets ({', '.join(str(p['cycle']) for p in partial)})"
              + (f", {skipped} left out (--skip-partial)" if skipped else ", used (--skip-partial leaves them out)"))
    above = {n: m for n, m in flags["methods"].items() if m["cycles_above_ratio_bound"]}
    if above:
        print(f"ratio > {flags['upward_ratio_bound']:g}   " + ", ".join(
            f"{n}: {m['cycles_above_ratio_bound']} {unit}(s), largest {m['worst_upward_ratio']:.3g}"
            for n, m in above.items()))
