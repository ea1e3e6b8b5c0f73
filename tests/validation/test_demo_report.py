"""The demo's report.md in a newcomer's words (built from made-up results; no render)."""

from __future__ import annotations

import json

from validation.demo import FIGURE_CAPTIONS, _report


def _vo(deltas):
    return {"n_frames": 12, "failures": [], "rpe": {"deltas": [
        {"delta_m": d, "n_pairs": n, "trans_percent": {"median": v} if n else None} for d, n, v in deltas]}}


def test_demo_report_names_the_selector_the_rpe_column_and_its_figures(tmp_path):
    out = tmp_path / "demo"
    run_dir = out / "run"
    run_dir.mkdir(parents=True)
    (run_dir / "results.json").write_text(json.dumps({"methods": {
        "fixed": {"median_exposure_ms": 4.0, "mean_saturated_fraction": 0.01},
        "kim": {"median_exposure_ms": 0.5, "mean_saturated_fraction": 0.0}}}))
    cfg = {"scene": "forest_winter", "n_cycles": 4, "width": 96, "height": 60, "spp": 4, "vo_ratio": 0.9}
    emu = {"per_target": {"3.0": {"median_rmse_percent": 0.2, "n": 8}}, "median_rmse_percent": 0.2,
           "max_rmse_percent": 0.4}
    feats = {"parameters": {"ratio": 0.8}, "methods": {"fixed": {"median_uniformity": 0.5, "median_matches": 52},
                                                        "kim": {"median_uniformity": 0.52, "median_matches": 50}}}
    # the longest pair length with pairs is 0.60 m for both (1.20 m has none): its medians are shown
    vo = {"methods": {"fixed": _vo([(0.3, 6, 9.0), (0.6, 3, 4.25), (1.2, 0, None)]),
                      "kim": _vo([(0.3, 6, 8.0), (0.6, 3, 5.5), (1.2, 0, None)])}}
    md = _report(out, cfg, emu, run_dir, feats, vo, {"total_s": 1.0}, tmp_path / "dataset", False)
    assert "## Emulation against exact ground truth (the paper's bracket selector: higher bracket unless saturated)" in md
    header = next(line for line in md.splitlines() if line.startswith("| method | median exposure"))
    assert header.endswith("| relative pose error, translation, median over pose pairs 0.60 m apart "
                           "(% of that distance) |")
    rows = {line.split("|")[1].strip(): line for line in md.splitlines() if line.startswith(("| fixed", "| kim"))}
    assert rows["fixed"].endswith("| 4.25 |") and rows["kim"].endswith("| 5.5 |")
    assert f"![{FIGURE_CAPTIONS['run/exposure.png']}](run/exposure.png)" in md
    for word in ("HigherNoSat", "longest delta", "paper mode", "M_fixed"):
        assert word not in md
    assert all("/" not in caption and ".png" not in caption for caption in FIGURE_CAPTIONS.values())
