"""Render study report: the markdown table and the time-against-error figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from validation.render_study.config import TARGET_REPEATABILITY, TARGET_TOLERANCE

__all__ = ["render_study_table", "plot_render_study"]


# ------------------------------------------------------------------------------------------ report
def _f(v, fmt="{:.3g}") -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "-"
    return fmt.format(v)


def _yes(v) -> str:
    return "-" if v is None else ("yes" if v else "**no**")


def render_study_table(results: dict) -> str:
    """The study's markdown report: the per-scene table, texture targets and speed-ups."""
    cfg = results["provenance"]["config"]
    real = (results.get("real") or {}).get(f"{cfg['width']}x{cfg['height']}")
    lines = [f"# Render study: raw vs denoised (OIDN) at {cfg['width']}x{cfg['height']}", "",
             f"Command: `{results['provenance']['experiment']}`", "",
             "Error: RMSE of noiseless captures at " + ", ".join(f"{e:g}" for e in cfg["error_exposures_ms"]) +
             " ms vs a raw reference, % of the DN range. Bright: brightest 0.1 % of the reference's pixels "
             "(relative RMS error; halo: mean luminance over the reference's - 1 within "
             f"{cfg['halo_px']} px). Repeatability: SIFT, 1.5 px. Flicker: static camera, mean |change| of the "
             f"noiseless {cfg['exposure_ms']:g} ms capture between frames, % of DN range (ratio: to the sensor "
             "noise's own frame-to-frame change). kp/MP and gradient at "
             f"{cfg['exposure_ms']:g} ms with sensor noise" +
             ("" if real is None else f"; real frames: {real['kp_per_mp']:.0f} kp/MP, gradient "
                                      f"{real['median_gradient']:.1f}") + ".", ""]
    for key, m in results["scenes"].items():
        lines += [f"## {key}", "",
                  f"Reference {m['reference_spp']} spp ("
                  f"{'from the render cache' if m.get('reference_cached') else format(m['reference_time_s'], '.0f') + ' s'}, "
                  f"{m['reference_dynamic_range_db']:.0f} dB, halo {m['reference_bright_halo']:+.3f} vs itself, "
                  f"{m['reference_kp_per_mp']:.0f} kp/MP); sensor frame-to-frame change "
                  f"{m['sensor_change_pct']:.3f} %." + (f" **OIDN fell back**: {m['fallback']}" if m['fallback']
                                                        else ""), "",
                  "| spp | denoise | time s | error % | bright err | halo | repeat seeds | repeat walk | "
                  "flicker % | flicker/sensor | kp/MP | gradient |",
                  "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in (r for r in results["rows"] if r["scene"] == key):
            lines.append(f"| {r['spp']} | {r['denoise_applied']} | {_f(r['time_s'])} | {_f(r['rmse_pct'])} | "
                         f"{_f(r['bright_rel_err'])} | {_f(r['bright_halo'], '{:+.3f}')} | "
                         f"{_f(r['repeat_seeds'], '{:.2f}')} | {_f(r['repeat_walk'], '{:.2f}')} | "
                         f"{_f(r['flicker_pct'])} | {_f(r['flicker_ratio'], '{:.2f}')} | "
                         f"{_f(r['kp_per_mp'], '{:.0f}')} | {_f(r['median_gradient'], '{:.1f}')} |")
        lines.append("")
    if results["speedups"]:
        lines += ["## Speed-up of the denoiser (raw time for the same error / denoised time)", "",
                  "| scene | denoiser | spp | denoised s | error % | raw s for that error | speed-up | target >= 10 |",
                  "|---|---|---:|---:|---:|---:|---:|---|"]
        for s in results["speedups"]:
            lines.append(f"| {s['scene']} | {s.get('denoise', 'oidn')} | {s['spp']} | {_f(s['denoised_time_s'])} | {_f(s['denoised_rmse_pct'])} | "
                         f"{_f(s['raw_time_same_error_s'])}{' (extrapolated)' if s['extrapolated'] else ''} | "
                         f"{_f(s['speedup'])} | {_yes(s['speedup'] >= 10)} |")
        lines.append("")
    if results["texture"]:
        lines += [f"## Texture vs real frames (denoised, {cfg['exposure_ms']:g} ms; target +-"
                  f"{100 * TARGET_TOLERANCE:.0f} %, repeatability >= {TARGET_REPEATABILITY:.2f})", "",
                  "| scene | size | spp | kp/MP | real | ratio | met | gradient | real | ratio | met | "
                  "repeat seeds | met |", "|---|---|---:|---:|---:|---:|---|---:|---:|---:|---|---:|---|"]
        for t in results["texture"]:
            lines.append(f"| {t['scene']} | {t['width']}x{t['height']} | {t['spp']} | {t['kp_per_mp']:.0f} | "
                         f"{_f(t['real_kp_per_mp'], '{:.0f}')} | {_f(t['kp_ratio'], '{:.2f}')} | {_yes(t['kp_met'])} | "
                         f"{t['median_gradient']:.1f} | {_f(t['real_median_gradient'], '{:.1f}')} | "
                         f"{_f(t['gradient_ratio'], '{:.2f}')} | {_yes(t['gradient_met'])} | "
                         f"{t['repeat_seeds']:.2f} | {_yes(t['repeat_met'])} |")
        lines.append("")
    lines.append(f"Total {results['timings']['total_s'] / 60:.1f} min.")
    return "\n".join(lines)


def plot_render_study(results: dict, path: Path) -> None:
    """The render study's figure, written to ``path``."""
    from emulator.report.figures import new_figure, save

    keys = list(results["scenes"])
    fig, axes = new_figure(len(keys), 5.0, 4.0)
    for ax, key in zip(axes, keys):
        for mode, style in (("off", "o-"), ("oidn", "s-"), ("oidn-fast", "^-")):
            rs = sorted((r for r in results["rows"] if r["scene"] == key and r["denoise"] == mode),
                        key=lambda r: r["spp"])
            if not rs:
                continue
            x = [r["time_s"] for r in rs]
            y = [max(r["rmse_pct"], 1e-6) for r in rs]
            ax.loglog(x, y, style, label={"off": "raw", "oidn": "denoised (OIDN)",
                                          "oidn-fast": "denoised (OIDN fast)"}[mode])
            for r, xi, yi in zip(rs, x, y):
                ax.annotate(str(r["spp"]), (xi, yi), textcoords="offset points", xytext=(3, 3), fontsize=7)
        ax.set_title(key)
        ax.set_xlabel("time per frame, s")
        ax.set_ylabel("RMSE vs reference, % of DN range")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    save(fig, path, dpi=110)
