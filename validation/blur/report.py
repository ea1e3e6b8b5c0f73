"""``report.md`` of the blur study."""

from __future__ import annotations

__all__ = ["report_markdown", "headline", "versus_markdown"]


def _f(v, spec=".3g") -> str:
    return "n/a" if v is None else format(v, spec)


def headline(r: dict) -> str:
    rates = r.get("angular_rate_ratio") or {}
    rate_text = ", ".join(f"{k} {_f(v)}" for k, v in rates.items()) or "n/a (no real gyro)"
    return (f"blur vs brute-force reference: {_f(r['reference_error_percent'])} % (its noise "
            f"{_f(r['reference_noise_percent'])} %, without blur {_f(r['reference_no_blur_error_percent'])} %); "
            f"render cost ratio {_f(r['render_cost_ratio'])} (goal <= {r['render_cost_ratio_goal']:g}); "
            f"angular rate ratio {rate_text}; sharpness error, plain emulation "
            f"{_f(r['sharpness_error_plain_percent'])} %, blur-consistent {_f(r['sharpness_error_consistent_percent'])} %"
            f"; consistent over plain: |sharpness error| {_f(r.get('sharpness_abs_error_ratio'))}, RMS image error "
            f"{_f(r.get('image_rms_error_ratio'))} (goal <= {_f(r.get('consistent_halves_error_goal'))})")


def report_markdown(r: dict) -> str:
    cfg = r["provenance"]["config"]
    lines = ["# Exposure-time blur: validation", "", headline(r), "",
             f"Scene {cfg['scene']}, walk {cfg['walk']}, {cfg['width']}x{cfg['height']}, {cfg['spp']} spp, "
             f"{cfg['exposure_ms']:g} ms windows; machine: {r['machine']['processor']}, variant "
             f"{r['machine']['variant']}.", "",
             "## Against the brute-force reference (noiseless captures, % of the DN range)", "",
             "| t0 (s) | blur (px) | sub-instants | error | reference noise | method noise | error / noise | "
             "without blur |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for row in r["reference"]:
        lines.append(f"| {row['t0_s']:.2f} | {_f(row['blur_px'])} | {row['n_subinstants']} | "
                     f"{_f(row['error_percent'])} | {_f(row['reference_noise_percent'])} | "
                     f"{_f(row['method_noise_percent'])} | {_f(row['error_over_noise'])} | "
                     f"{_f(row['no_blur_error_percent'])} |")
    lines += ["", "### Error against the number of sub-instants (one render, warped n times)", "",
              "| t0 (s) | " + " | ".join(f"n={row['n_subinstants']}" for row in r["reference"][0]["by_subinstants"])
              + " |", "| --- |" + " --- |" * len(r["reference"][0]["by_subinstants"])]
    for row in r["reference"]:
        lines.append(f"| {row['t0_s']:.2f} | " + " | ".join(
            f"{_f(x['error_percent'])} % / {1e3 * x['warp_s']:.1f} ms" for x in row["by_subinstants"]) + " |")
    if r["reference"][0].get("by_interpolation"):
        lines += ["", "### Resampler of the warps (the same two renders)", "",
                  "| t0 (s) | resampler | error | method noise | error / noise | warps (s) |",
                  "| --- | --- | --- | --- | --- | --- |"]
        for row in r["reference"]:
            for x in row["by_interpolation"]:
                lines.append(f"| {row['t0_s']:.2f} | {x['interpolation']} | {_f(x['error_percent'])} | "
                             f"{_f(x['method_noise_percent'])} | {_f(x['error_over_noise'])} | {_f(x['warp_s'])} |")
    lines += ["", "## Cost (CPU seconds of this process and its children; wall seconds beside)", ""]
    for label, key in (("fastest turn", "cost"), ("median turn rate", "cost_median_rate")):
        c = r.get(key)
        if c is None:
            continue
        lines.append(f"- {label} (t0 {_f(c.get('t0_s'))} s): at rest {_f(c.get('at_rest_cpu_s'))} CPU s "
                     f"({_f(c['at_rest_s'])} s wall), blurred {_f(c.get('blurred_cpu_s'))} CPU s "
                     f"({_f(c['blurred_s'])} s wall; {c['n_subinstants']} sub-instants, {c['margin_px']} px margin, "
                     f"warps {_f(c['warp_s'])} s, depth {_f(c['depth_s'])} s): ratio {_f(c['render_cost_ratio'])} "
                     f"(wall {_f(c.get('render_cost_ratio_wall'))}; load {c.get('load_average_1min')})")
    lines += ["", "## Angular rate (deg/s)", ""]
    a = r["angular_rate"]
    for name, key in (("synthetic", "synthetic_deg_s"), ("real", "real_deg_s")):
        vals = a.get(key)
        lines.append(f"- {name}: " + ("n/a" if vals is None else ", ".join(f"{k} {v:.2f}" for k, v in vals.items())))
    size = (f"{cfg['sharpness_width']}x{cfg['sharpness_height']}" if "sharpness_width" in cfg
            else f"{cfg['width']}x{cfg['height']}")
    lines += ["", f"## Sharpness: emulated against live (p95 gradient / median, green plane; {size})", "",
              "| t0 (s) | blur (px) | live | emulated (plain) | error % | consistent error % | RMS DN, plain | "
              "RMS DN, consistent |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for row in r["sharpness"]:
        lines.append(f"| {row['t0_s']:.2f} | {_f(row['blur_px'])} | {_f(row['live'])} | "
                     f"{_f(row['emulated_plain'])} | {_f(row['plain_error_percent'])} | "
                     f"{_f(row['consistent_error_percent'])} | {_f(row.get('rms_plain_dn'))} | "
                     f"{_f(row.get('rms_consistent_dn'))} |")
    lines += versus_markdown(r.get("live_versus_emulated"))
    lines += ["", f"Command: `{r['provenance']['experiment']}`", ""]
    return "\n".join(lines)


def _diff(cell: dict) -> str:
    d = cell["per_walk"] if cell.get("basis") == "walks" else cell.get("per_frame") or cell["per_walk"]
    if d is None or d.get("estimate") is None:
        return f"n/a ({cell['verdict']})"
    ci = d.get("ci95")
    ci_text = "" if ci is None else f" [{ci[0]:.3g}, {ci[1]:.3g}]"
    return f"{d['estimate']:+.3g}{ci_text} {cell['verdict']}"


def versus_markdown(v: dict | None) -> list[str]:
    """The live-against-emulated table: emulated minus live, 95 % interval, verdict."""
    if not v:
        return []
    table = v["table"]
    metrics = list(next(iter(next(iter(table.values())).values())))
    lines = ["", "## Live against emulated, with blur and without (emulated minus live)", "",
             f"{len(v['walks'])} walk(s); live timing {v['settings']['live_timing']}; intervals over walks where "
             "there are two or more, else (features) over frames; verdicts against the live study's "
             "equivalence margins.", "",
             "| recording / run | method | " + " | ".join(metrics) + " |", "| --- | --- |" + " --- |" * len(metrics)]
    for key, rows in table.items():
        for m, row in rows.items():
            lines.append(f"| {key} | {m} | " + " | ".join(_diff(row[k]) for k in metrics) + " |")
    return lines
