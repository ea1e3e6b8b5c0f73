"""Calibration study report: the plots and ``report.md``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from emulator.io.files import save_figure
from emulator.report.figures import subplots
from validation.calibration_study.config import DN_RANGE, PRESETS



# ---------------------------------------------------------------------------- report
def calibration_plots(results: dict, arrays: dict, out: Path) -> list[str]:
    """The calibration study's plots written into ``out``; their file names."""
    names = []
    presets = [p for p in PRESETS if f"{p}_truth" in arrays]
    if presets:
        fig, axes = subplots(2, len(presets), figsize=(4.2 * len(presets), 7), squeeze=False)
        for j, p in enumerate(presets):
            gt = arrays[f"{p}_truth"]
            dn = np.arange(gt.size)
            ax, axe = axes[0, j], axes[1, j]
            ax.plot(dn, gt, "k-", lw=2, label="true")
            for key, style, label in (("ours", "C0-", "ours 12-bit"), ("ours8", "C0:", "ours 8-bit"),
                                      ("debevec", "C1--", "Debevec 8-bit"), ("robertson", "C2-.", "Robertson 8-bit")):
                g = arrays[f"{p}_{key}"][: gt.size]
                sl = slice(DN_RANGE[0], DN_RANGE[1] + 1)
                s = float(np.dot(g[sl], gt[sl]) / np.dot(g[sl], g[sl]))
                ax.plot(dn, g * s, style, lw=1, label=label)
                axe.plot(dn[sl], (g[sl] * s - gt[sl]) / (gt[-1] - gt[0]) * 100, style, lw=1, label=label)
            ax.set_title(f"{p}: f^-1 (scale-aligned)")
            ax.set_xlabel("DN")
            ax.legend(fontsize=7)
            axe.set_title("error, % of range")
            axe.set_xlabel("DN")
            axe.set_ylim(-3, 3)
            axe.grid(alpha=0.3)
        fig.tight_layout()
        save_figure(fig, out / "static_stacks.png", dpi=100)
        names.append("static_stacks.png")
    ins = [p for p in PRESETS if f"insitu_{p}_truth" in arrays]
    if ins:
        fig, axes = subplots(1, len(ins), figsize=(4.2 * len(ins), 3.6), squeeze=False)
        for j, p in enumerate(ins):
            gt, g = arrays[f"insitu_{p}_truth"], arrays[f"insitu_{p}_recovered"][: arrays[f"insitu_{p}_truth"].size]
            sl = slice(DN_RANGE[0], DN_RANGE[1] + 1)
            s = float(np.dot(g[sl], gt[sl]) / np.dot(g[sl], g[sl]))
            axes[0, j].plot(gt, "k-", lw=2, label="true")
            axes[0, j].plot(g * s, "C3-", lw=1, label="in situ")
            axes[0, j].set_title(f"in situ, moving, {p}")
            axes[0, j].set_xlabel("DN")
            axes[0, j].legend(fontsize=8)
        fig.tight_layout()
        save_figure(fig, out / "in_situ_synthetic.png", dpi=100)
        names.append("in_situ_synthetic.png")
    real = results.get("real_sample", {})
    if "real_pcalib" in arrays:
        fig, (ax, axb) = subplots(1, 2, figsize=(12, 4))
        gt = arrays["real_pcalib"]
        ax.plot(gt, "k-", lw=2, label="pcalib_inside1")
        for key, style in (("both", "C3-"), ("left", "C0--"), ("right", "C2:")):
            g = arrays[f"real_in_situ_{key}"]
            sl = slice(16, 3001)
            s = float(np.dot(g[sl], gt[sl]) / np.dot(g[sl], g[sl]))
            ax.plot(g * s, style, lw=1, label=f"in situ ({key}), scaled on DN 16..3000")
        ax.set_xlabel("DN")
        ax.set_title("real sample: inverse response")
        ax.legend(fontsize=8)
        for k, (rname, style) in enumerate((("pcalib_inside1", "ko"), ("in_situ_both", "C3s"), ("linear", "C7^"))):
            pr = real["pairs"][rname]
            axb.semilogy(np.arange(len(pr)), [p["rmse_pct"] for p in pr], style, ms=4, label=rname)
        axb.set_xlabel("emulation (cycle, camera, source -> target)")
        axb.set_ylabel("quantile RMSE, % of range")
        axb.set_title("cross-bracket error per emulation")
        axb.legend(fontsize=8)
        axb.grid(alpha=0.3, which="both")
        fig.tight_layout()
        save_figure(fig, out / "real_sample.png", dpi=100)
        names.append("real_sample.png")
    return names


def _f(v, d=3):
    return "n/a" if v is None else f"{v:.{d}f}"


def calibration_markdown(results: dict, figures: list[str]) -> str:
    """The calibration study's ``report.md`` text."""
    cfg = results["config"]
    lines = ["# Inverse-response calibration: validation", "",
             f"Command: `{results['command']}`  ", f"Radiance of the static stacks: {results['radiance']}  ",
             f"Stacks: {cfg['n_exposures']} exposures each, jittered log spacing, noise on (synth presets: full "
             f"well 10500 e-, read noise 2.4 e-), {cfg['width']}x{cfg['height']} Bayer, "
             f"{cfg['max_pixels']} pixels sampled.  Errors: f^-1 over DN {DN_RANGE[0]}..{DN_RANGE[1]} in % of "
             "its range after scale alignment (f^-1 is defined up to scale); 'as written' normalises both to "
             "g(top) = 255 like the pcalib file.", ""]
    st = results.get("static", {})
    if st:
        methods = ["ours_12bit", "ours_12bit_at_8bit_bin_centres", "ours_8bit", "opencv_debevec_8bit",
                   "opencv_robertson_8bit"]
        extra = [m for m in ("ours_12bit_geometric_exposures", "ours_12bit_als_500_iterations")
                 if any(m in st[p]["errors"] for p in st)]
        lines += ["## Recovery error of f^-1 (max / RMS, % of range, DN 16..4079)", "",
                  "| method | " + " | ".join(st) + " |", "|---" * (len(st) + 1) + "|"]
        for m in methods + extra:
            cells = []
            for p in st:
                e = st[p]["errors"].get(m)
                cells.append("-" if e is None else f"{_f(e['max_pct'])} / {_f(e['rms_pct'])}")
            lines.append(f"| {m} | " + " | ".join(cells) + " |")
        lines.append("| ours_12bit as written (g(top)=255) | " + " | ".join(
            f"{_f(st[p]['errors']['ours_12bit']['max_pct_as_written'])} / "
            f"{_f(st[p]['errors']['ours_12bit']['rms_pct_as_written'])}" for p in st) + " |")
        lines += ["", "8-bit rows: inputs DN >> 4, curves compared at the bin centres DN 16 v + 7.5 of codes "
                  "1..254.  Target: ours below 0.5 % max.",
                  "", "## Fit and emulation with the recovered response", "",
                  "Emulation: 1..32 bracket set (longest saturating ~3 %), targets halfway between brackets, "
                  "each from both bounding brackets, against the noiseless capture; RMSE over the validity "
                  "mask.  'pcalib format' is the true curve sampled at the 256 pcalib knots.", "",
                  "| preset | observed DN | residual DN RMS | noise DN (image estimate) | exposures span | "
                  "max abs(RMSE_rec / RMSE_true - 1) | same, true in pcalib format | max abs(RMSE_rec / RMSE_format - 1) "
                  "| max RMSE_true % | max RMSE(rec - true emulation) % |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for p, r in st.items():
            f, em = r["fit"], r["emulation"]
            lines.append(f"| {p} | {f['observed_dn'][0]}..{f['observed_dn'][1]} | {_f(f['residual_rms_dn'], 2)} | "
                         f"{_f(f['noise_dn'], 2)} | {_f(r['exposure_span_decades'], 1)} decades | "
                         f"{_f(em['max_abs_ratio_minus_1'])} | {_f(em['max_abs_format_ratio_minus_1'])} | "
                         f"{_f(em['max_abs_ratio_to_format_minus_1'])} | {_f(em['max_rmse_true_pct'])} | "
                         f"{_f(em['max_recovered_vs_true_emulation_pct'])} |")
        b = st.get("borealhdr", {}).get("borealhdr_table")
        if b and "skipped" not in b:
            lines += ["", "## BorealHDR: recovered vs the real table pcalib_inside1", "",
                      "| comparison | max % (scale) | RMS % (scale) | max % (as written) |", "|---|---|---|---|"]
            for name, v in b.items():
                lines.append(f"| {name} | {_f(v['scale']['max_pct'])} | {_f(v['scale']['rms_pct'])} | "
                             f"{_f(v['top']['max_pct'])} |")
    ins = results.get("in_situ_synthetic", {})
    if ins:
        lines += ["", "## In situ on synthetic moving recordings", "",
                  "| preset | sweeps | observed DN | max % 16..4079 | RMS % | max % observed | cross-bracket median %: recovered / true / linear |",
                  "|---|---|---|---|---|---|---|"]
        for p, r in ins.items():
            s = r["cross_bracket_median_pct"]
            lines.append(f"| {p} | {r['n_sweeps']} | {r['observed_dn'][0]}..{r['observed_dn'][1]} | "
                         f"{_f(r['error_16_4079']['max_pct'], 2)} | {_f(r['error_16_4079']['rms_pct'], 2)} | "
                         f"{_f(r['error_observed']['max_pct'], 2)} | {_f(s['recovered'])} / {_f(s['true'])} / "
                         f"{_f(s['linear'])} |")
    real = results.get("real_sample", {})
    if real and "skipped" not in real:
        sc = real["scores"]
        lines += ["", "## Real BorealHDR sample: cross-bracket error (median %, reference: pcalib 0.56-0.60, linear 9.6)",
                  "", real["method"], "", "| response | both cameras | left | right |", "|---|---|---|---|"]
        for rname, v in sc.items():
            lines.append(f"| {rname} | {_f(v['both']['median_pct'])} | {_f(v['left']['median_pct'])} | "
                         f"{_f(v['right']['median_pct'])} |")
        v = real["median_1000_quantiles_0_to_1"]
        lines += ["", "With 1000 quantile levels 0..1 instead: " + ", ".join(f"{k} {_f(x)}" for k, x in v.items()),
                  "", "In-situ shape vs pcalib (scale-aligned, max / RMS %): " + "; ".join(
                      f"{k}: DN 16..3000 {_f(s['16_3000']['max_pct'], 2)} / {_f(s['16_3000']['rms_pct'], 2)}, "
                      f"DN 16..4079 {_f(s['16_4079']['max_pct'], 2)} / {_f(s['16_4079']['rms_pct'], 2)}"
                      for k, s in real["in_situ_vs_pcalib_shape"].items())]
    lines += [""] + [f"![{f}]({f})" for f in figures] + [""]
    return "\n".join(lines)
