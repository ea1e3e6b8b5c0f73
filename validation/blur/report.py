"""``report.md`` of the blur study."""

from __future__ import annotations

__all__ = ["report_markdown", "headline"]


def _f(v, spec=".3g") -> str:
    return "n/a" if v is None else format(v, spec)


def headline(r: dict) -> str:
    rates = r.get("angular_rate_ratio") or {}
    rate_text = ", ".join(f"{k} {_f(v)}" for k, v in rates.items()) or "n/a (no real gyro)"
    return (f"blur vs brute-force reference: {_f(r['reference_error_percent'])} % (its noise "
            f"{_f(r['reference_noise_percent'])} %, without blur {_f(r['reference_no_blur_error_percent'])} %); "
            f"render cost ratio {_f(r['render_cost_ratio'])} (goal <= {r['render_cost_ratio_goal']:g}); "
            f"angular rate ratio {rate_text}; sharpness error, plain emulation "
            f"{_f(r['sharpness_error_plain_percent'])} %, blur-consistent {_f(r['sharpness_error_consistent_percent'])} %")


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
    c = r["cost"]
    lines += ["", "## Cost", "", f"At rest {_f(c['at_rest_s'])} s, blurred {_f(c['blurred_s'])} s "
              f"({c['n_subinstants']} sub-instants, {c['margin_px']} px margin, warps {_f(c['warp_s'])} s, depth "
              f"{_f(c['depth_s'])} s): ratio {_f(c['render_cost_ratio'])}.", "",
              "## Angular rate (deg/s)", ""]
    a = r["angular_rate"]
    for name, key in (("synthetic", "synthetic_deg_s"), ("real", "real_deg_s")):
        vals = a.get(key)
        lines.append(f"- {name}: " + ("n/a" if vals is None else ", ".join(f"{k} {v:.2f}" for k, v in vals.items())))
    lines += ["", "## Sharpness: emulated against live (p95 gradient / median, green plane)", "",
              "| t0 (s) | blur (px) | live | emulated (plain) | error % | consistent error % |",
              "| --- | --- | --- | --- | --- | --- |"]
    for row in r["sharpness"]:
        lines.append(f"| {row['t0_s']:.2f} | {_f(row['blur_px'])} | {_f(row['live'])} | "
                     f"{_f(row['emulated_plain'])} | {_f(row['plain_error_percent'])} | "
                     f"{_f(row['consistent_error_percent'])} |")
    lines += ["", f"Command: `{r['provenance']['experiment']}`", ""]
    return "\n".join(lines)
